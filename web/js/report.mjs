// A printable test report for one campaign (report.html?id=N), from GET /api/campaigns/{id}/report
// (imucal-test-report/1): the unit, the run's conditions (site gravity, temperatures, rate,
// duration), then per test (IEEE 952 rate steps, warm-up and repeatability, IEEE 1293 tumble, any
// calibration stage) its standard, its conditions and every figure with its standard uncertainty,
// and the verdict where the part number limits a figure. Numbers are rounded as the certificate
// rounds them (certificate_rows.mjs).
import { api, ApiError } from './api.mjs';
import { h, clear, fill, dateTime, duration, num } from './format.mjs';
import { roundedNumbers, gravityStatement } from './certificate_rows.mjs';
import { coefficientName, unitOf } from './coefficients.mjs';
import { loadSchema } from './schema.mjs';

const sheet = document.getElementById('report');
const id = Number(new URLSearchParams(location.search).get('id'));
document.getElementById('print').addEventListener('click', () => window.print());

const UNITS = { 'deg/h': '°/h', ug: 'µg', ppm: 'ppm', s: 's', 'ppm of full scale': 'ppm of full scale' };

async function load() {
  if (!Number.isInteger(id) || id < 1) {
    clear(sheet).append(h('p', { class: 'error' }, 'No campaign given: open this page from a campaign\'s results (report.html?id=N).'));
    return;
  }
  document.getElementById('report-json').href = `/api/campaigns/${id}/report`;
  document.getElementById('report-json').download = `test-report-campaign-${id}.json`;
  let report;
  try {
    report = await api('GET', `/api/campaigns/${id}/report`, undefined, { auth: false });
    await loadSchema((path) => api('GET', path, undefined, { auth: false }));  // the coefficients' names (schema.mjs)
  } catch (e) {
    const text = e instanceof ApiError && e.status === 401
      ? 'Sign in to imucal first (in the main page), then reload this page.'
      : `Cannot make the report: ${e.message}`;
    clear(sheet).append(h('p', { class: 'error', id: 'report-error' }, text));
    return;
  }
  if (report.signed_by) {
    const signed = document.getElementById('report-signed');
    signed.href = `/api/campaigns/${id}/report?signed=1`;
    signed.download = `test-report-campaign-${id}.signed.json`;
    signed.hidden = false;
  }
  render(report);
}

// A figure's name and unit: the test's own, or the model's name of a coefficient key.
function nameOf(f) { return f.name === f.key ? coefficientName(f.key) : f.name; }
function unitOfFigure(f) { return f.unit ? (UNITS[f.unit] || f.unit) : unitOf(f.key); }

// Counts as integers, quantities with four significant digits.
const value = (x) => (typeof x !== 'number' ? String(x) : Number.isInteger(x) ? String(x) : num(x, 4));

function conditionsText(c) {
  const parts = [];
  for (const [k, v] of Object.entries(c || {})) {
    if (v === null || v === undefined) continue;
    const label = k.replace(/_/g, ' ');
    if (Array.isArray(v)) parts.push(`${label}: ${v.map(value).join(', ')}`);
    else if (typeof v === 'object') parts.push(`${label}: ${Object.entries(v).map(([a, b]) => `${a} ${value(b)}`).join('; ')}`);
    else parts.push(`${label}: ${value(v)}`);
  }
  return parts.length ? `Conditions: ${parts.join(' · ')}.` : '';
}

function figureTable(test, judged) {
  const body = h('tbody');
  for (const f of test.figures) {
    const n = f.value === null ? null : roundedNumbers({ value: f.value, u: f.u > 0 ? f.u : null, U: f.u > 0 ? 2 * f.u : null });
    const cells = n === null
      ? [h('td', { class: 'nd', colspan: 2 }, f.note || 'not determined')]
      : [h('td', { class: 'num' }, n.value), h('td', { class: 'num' }, n.u ?? '—')];
    const tr = h('tr', { dataset: { key: f.key }, class: f.pass === false ? 'fail' : null },
      h('td', { class: 'name' }, nameOf(f)), ...cells, h('td', {}, unitOfFigure(f)));
    if (f.interval_68) tr.append(h('td', { class: 'small-cell' }, `68 %: ${num(f.interval_68[0], 3)} … ${num(f.interval_68[1], 3)}`));
    else if (judged) tr.append(h('td'));
    if (judged) {
      tr.append(h('td', { class: `result ${f.pass === undefined ? '' : f.pass ? 'pass' : 'fail'}` },
        f.pass === undefined ? '' : f.pass ? `pass (limit ${num(f.limit_value, 3)})` : `FAIL: ${f.reason}`));
    }
    body.append(tr);
  }
  const hasIntervals = test.figures.some((f) => f.interval_68);
  return h('table', { class: 'coefficients', dataset: { test: test.test } },
    h('thead', {}, h('tr', {}, h('th', {}, 'Figure'), h('th', { class: 'num' }, 'Value'), h('th', { class: 'num' }, 'u (k = 1)'),
      h('th', {}, 'Unit'), ...(hasIntervals || judged ? [h('th', {}, hasIntervals ? 'Interval' : '')] : []),
      ...(judged ? [h('th', {}, 'Limit')] : []))),
    body);
}

// PASS, or FAIL naming each coefficient that failed and why (a limited coefficient the run did
// not determine fails too, and is in no test's table).
function verdictText(v) {
  if (!v) return 'no acceptance limits for this unit: not judged';
  const head = `${v.pass ? 'PASS' : 'FAIL'} against the limits of part number ${v.part_number}`;
  if (v.pass) return head;
  const failed = (v.failed || []).map((f) => `${coefficientName(f.key)} (${f.key}): ${f.reason}`);
  return failed.length ? `${head}: ${failed.join('; ')}` : `${head} (${v.failures} outside)`;
}

function render(r) {
  const c = r.conditions || {};
  const t = c.temperatures;
  document.title = `Test report: campaign ${r.campaign.id}`;
  const judged = Boolean(r.verdict);
  const facts = [
    ['IMU serial number', r.unit.serial || 'not recorded'],
    ['Part number', r.unit.identity?.part_number || '—'],
    ['Campaign', `${r.campaign.id} "${r.campaign.name}", program ${r.campaign.program}, ${r.campaign.state}`],
    ['Run', `${dateTime(r.campaign.started)} – ${dateTime(r.campaign.ended)} (local time)`],
    ['Duration', `${duration(c.program_time_s)} of ${duration(c.duration_s)} of program, ${c.frames ?? '—'} frames at ${num(c.rate_hz, 4)} Hz`],
    ['Gravity', gravityStatement(c.gravity)],
    ['Temperatures', t ? `chamber ${num(t.chamber_C.min, 3)} … ${num(t.chamber_C.max, 3)} °C (mean ${num(t.chamber_C.mean, 3)}), ` +
      `IMU ${num(t.imu_C.min, 3)} … ${num(t.imu_C.max, 3)} °C (mean ${num(t.imu_C.mean, 3)}), ${t.samples} readings` : 'not recorded'],
    ['Verdict', verdictText(r.verdict)],
  ];
  fill(sheet,
    c.simulated ? h('div', { class: 'watermark', 'aria-hidden': 'true' }, 'SIMULATION') : null,
    h('header', {}, h('h1', {}, 'Test report'), h('p', { class: 'number', id: 'report-campaign' }, `campaign ${r.campaign.id}`)),
    c.simulated ? h('p', { class: 'sim-note' }, 'Made with simulated devices: this documents a simulation, not a physical instrument.') : null,
    h('table', { class: 'facts' }, h('tbody', {}, ...facts.map(([k, v]) => h('tr', {}, h('th', {}, k), h('td', { dataset: { fact: k } }, v))))),
    h('p', { class: 'small' }, 'u (k = 1): standard uncertainty, the estimator\'s 1 σ; numbers rounded to u\'s second significant digit.'),
    ...(r.tests.length ? r.tests.flatMap((test) => [
      h('h2', { id: `test-${test.test}` }, test.title),
      h('p', { class: 'small' }, `${test.standard}. ${conditionsText(test.conditions)}`),
      figureTable(test, judged)]) : [h('p', { class: 'error', id: 'no-tests' }, 'This run has no finished test or calibration stage.')]),
    // A signed copy: the lab's key's fingerprint and the command that checks a download offline.
    h('p', { class: 'small verification', id: 'report-verification' }, r.signed_by
      ? ['Signed with the lab\'s key ', r.signed_by, ': "Signed JSON" above downloads it; check it with ',
        h('code', {}, `imucal verify test-report-campaign-${r.campaign.id}.signed.json --fingerprint ${r.signed_by}`), '.']
      : 'Not signed (the lab has configured no key).'),
    h('footer', {}, `Test report of campaign ${r.campaign.id} by imucal (${r.format}); printed ${dateTime(new Date().toISOString())}. ` +
      'GET /api/campaigns/' + r.campaign.id + '/report gives the same figures as JSON.'));
  sheet.dataset.ready = 'true';
}

load();
