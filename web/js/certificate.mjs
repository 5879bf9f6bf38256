// A printable calibration certificate for one campaign (certificate.html?id=N): the IMU, date,
// site, campaign and coefficients with their 1-sigma uncertainties, laid out for an A4 page.
// "Download HTML" saves it as one self-contained file (styles inlined, no scripts), so it can be
// archived or mailed and still print the same.
import { api, ApiError } from './api.mjs';
import { h, clear, dateTime, num, FINAL_STATES } from './format.mjs';
import { coefficientRows } from './coefficients.mjs';

const sheet = document.getElementById('certificate');
const message = document.getElementById('toolbar-message');
const id = Number(new URLSearchParams(location.search).get('id'));

document.getElementById('print').addEventListener('click', () => window.print());
document.getElementById('save-html').addEventListener('click', saveHtml);

async function load() {
  if (!Number.isInteger(id) || id < 1) {
    clear(sheet).append(h('p', { class: 'error' }, 'No campaign given: open this page from a campaign\'s results (certificate.html?id=N).'));
    return;
  }
  const get = (path) => api('GET', path, undefined, { auth: false });
  let detail, model, status;
  try {
    [detail, status] = await Promise.all([get(`/api/campaigns/${id}`), get('/api/status')]);
    model = await get(`/api/campaigns/${id}/model`);
  } catch (e) {
    const text = e instanceof ApiError && e.status === 401
      ? 'Sign in to imucal first (in the main page), then reload this page.'
      : `Cannot make the certificate: ${e.message}`;
    clear(sheet).append(h('p', { class: 'error', id: 'certificate-error' }, text));
    return;
  }
  render(detail, model, status);
}

function render(d, model, status) {
  const ended = d.ended || d.created;
  const day = (ended || '').slice(0, 10).replace(/-/g, '');
  const number = `IMUCAL-${d.id}-${day}`;
  const site = status.site || {};
  const simulated = (status.devices || '').startsWith('sim');
  // The serial the run file records (GET /api/campaigns/{id}: imu_serial): the campaign's unit's
  // when it names one.
  const serial = d.imu_serial || d.imu?.serial || null;
  const unit = d.imu || {};
  document.title = `Calibration certificate ${number}`;
  const rows = coefficientRows(model, null).filter((r) => r.estimated && (r.sigma !== null || r.group === 'Noise'));
  const body = h('tbody');
  let group = null;
  for (const r of rows) {
    if (r.group !== group) {
      group = r.group;
      body.append(h('tr', { class: 'group' }, h('th', { colspan: 4 }, group)));
    }
    body.append(h('tr', {}, h('td', {}, r.name.split('.').slice(1).join('.')), h('td', { class: 'num' }, num(r.estimate, 5)),
      h('td', { class: 'num' }, r.sigma === null ? '—' : `± ${num(r.sigma, 2)}`), h('td', {}, r.unit)));
  }
  const facts = [
    ['Certificate number', number],
    ['IMU serial number', serial || 'not recorded (the campaign was never started)'],
    ...[['Part number', unit.part_number], ['Firmware', unit.firmware], ['Customer', unit.customer]].filter(([, v]) => v),
    ['Date of calibration', `${dateTime(d.started)} – ${dateTime(d.ended)} (local time)`],
    ['Date of issue', dateTime(new Date().toISOString())],
    ['Site', `${site.name || '—'}; latitude ${num(site.latitude_deg, 6)}°, longitude ${num(site.longitude_deg, 6)}°, height ${num(site.height_m, 4)} m; middle axis azimuth ${num(site.middle_axis_azimuth_deg, 4)}°`],
    ['Campaign', `${d.id} "${d.name}", program ${d.program}, ${d.frames ?? '—'} frames (${d.lost_frames ?? 0} lost, ${d.bad_frames ?? 0} bad)`],
    ['Chamber', d.spec?.chamber ? `${d.spec.chamber.setpoint_C} °C ± ${d.spec.chamber.tolerance_C} °C${d.spec.chamber.steps?.length ? `, ${d.spec.chamber.steps.length} set-point steps` : ''}` : '—'],
    ['Method', `${(d.spec?.estimators || []).join(', ') || '—'} estimation on a three-axis rate table (imucald ${status.version || ''}); model ${model.format || ''}, ${model.frame || 'instrument'} frame`],
    ['Final state', d.state + (d.error ? ` (${d.error})` : '') +
      (FINAL_STATES.has(d.state) && !d.complete ? ` — partial: ended at ${Math.round(100 * (d.progress || 0))} % of the program${d.accepted ? `, accepted by ${d.accepted.by}: ${d.accepted.reason}` : ''}` : '')],
  ];
  clear(sheet).append(
    simulated ? h('div', { class: 'watermark', 'aria-hidden': 'true' }, 'SIMULATION') : null,
    h('header', {}, h('h1', {}, 'Calibration certificate'), h('p', { class: 'number' }, number)),
    simulated ? h('p', { class: 'sim-note' }, 'Made with simulated devices: this documents a simulation, not a physical instrument.') : null,
    h('table', { class: 'facts' }, h('tbody', {}, ...facts.map(([k, v]) => h('tr', {}, h('th', {}, k), h('td', { dataset: { fact: k } }, v))))),
    h('h2', {}, 'Coefficients'),
    h('p', { class: 'small' }, 'Estimates with their standard uncertainties (1 σ, k = 1) from the estimator\'s covariance. Sensor error model and sign conventions: imucal CONVENTIONS.md (seed eq. 1).'),
    h('table', { class: 'coefficients', id: 'certificate-coefficients' },
      h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, 'Estimate'), h('th', { class: 'num' }, 'Uncertainty (1 σ)'), h('th', {}, 'Unit'))), body),
    h('div', { class: 'signatures' },
      h('div', {}, h('span', { class: 'line' }), 'Operator'), h('div', {}, h('span', { class: 'line' }), 'Checked by'), h('div', {}, h('span', { class: 'line' }), 'Date')),
    h('footer', {}, `Generated by imucal from campaign ${d.id} on ${dateTime(new Date().toISOString())}. The model JSON of this campaign is the authoritative form of these coefficients.`));
  sheet.dataset.ready = 'true';
}

async function saveHtml() {
  try {
    const css = await (await fetch('css/certificate.css')).text();
    const doc = document.documentElement.cloneNode(true);
    for (const el of doc.querySelectorAll('script, link[rel="stylesheet"], .no-print')) el.remove();
    const style = document.createElement('style');
    style.textContent = css;
    doc.querySelector('head').append(style);
    const html = `<!doctype html>\n${doc.outerHTML}\n`;
    const url = URL.createObjectURL(new Blob([html], { type: 'text/html' }));
    const a = h('a', { href: url, download: `certificate-campaign-${id}.html` });
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 1000);
    message.textContent = 'Saved.';
  } catch (e) {
    message.textContent = `Cannot save: ${e.message}`;
  }
}

load();
