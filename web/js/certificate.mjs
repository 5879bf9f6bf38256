// A printable calibration certificate for one campaign (certificate.html?id=N), laid out for one
// A4 page: its number (issued by the daemon), the unit, the dates, the site and its gravity, the
// reference equipment, the coefficients by name with standard (k = 1) and expanded (k = 2)
// uncertainties, the verdict against the part number's limits, a partial run marked as such, and
// the conventions. What it says is built by certificate_rows.mjs (pure, unit-tested).
// "Download HTML" saves it as one self-contained file (styles inlined, no scripts), so it can be
// archived or mailed and still print the same.
import { api, ApiError } from './api.mjs';
import { h, clear, fill, dateTime, num } from './format.mjs';
import {
  certificateRows, verdictStatement, partialStatement, overrideStatement, equipmentLines, gravityStatement, conventionsText,
  roundedNumbers, UNCERTAINTY_TEXT, COVERAGE_K, NOT_DETERMINED,
} from './certificate_rows.mjs';
import { budgetTable, sourceName } from './budget.mjs';
import { coefficientName, unitOf } from './coefficients.mjs';
import { loadSchema } from './schema.mjs';

const sheet = document.getElementById('certificate');
const message = document.getElementById('toolbar-message');
const query = new URLSearchParams(location.search);
const id = Number(query.get('id'));
const wantedNumber = query.get('number');
let issued = null;  // the certificate record as issued, for the signed download

document.getElementById('print').addEventListener('click', () => window.print());
document.getElementById('save-html').addEventListener('click', saveHtml);
document.getElementById('save-json').addEventListener('click', saveJson);
// The certificate is one A4 page; the budget annex (shown on screen) prints when asked for.
const printAnnex = document.getElementById('print-annex');
printAnnex.addEventListener('change', () => sheet.classList.toggle('with-annex', printAnnex.checked));

async function load() {
  if (!wantedNumber && (!Number.isInteger(id) || id < 1)) {
    clear(sheet).append(h('p', { class: 'error' }, 'No campaign given: open this page from a campaign\'s results (certificate.html?id=N, or ?number=NUMBER).'));
    return;
  }
  const get = (path) => api('GET', path, undefined, { auth: false });
  let record;
  try {
    // The certificate as issued (docs/api.md "Certificates"): the page shows its frozen content
    // and nothing read today, so it prints the same as the day it was issued.
    record = await get(wantedNumber ? `/api/certificates/${encodeURIComponent(wantedNumber)}` : `/api/campaigns/${id}/certificate`);
    await loadSchema(get);  // the coefficients' names (schema.mjs)
  } catch (e) {
    const text = e instanceof ApiError && e.status === 401
      ? 'Sign in to imucal first (in the main page), then reload this page.'
      : `Cannot make the certificate: ${e.message}`;
    clear(sheet).append(h('p', { class: 'error', id: 'certificate-error' }, text));
    return;
  }
  issued = record;
  const c = record.content;
  render(c.campaign, c.model, { site: c.site, version: c.software?.imucald }, { ...c.bench, number: record.number, issued: record.issued },
    record);
  await keepPage(record);
}

// The page as printed, stored once with the issued record (PUT /api/certificates/{number}/page):
// the first opening by an operator sends it; a viewer's opening leaves it to an operator's. The
// toolbar then offers the stored bytes, which a later reprint can be compared with.
async function keepPage(record) {
  let page = record.page;
  if (!page) {
    try {
      page = await api('PUT', `/api/certificates/${encodeURIComponent(record.number)}/page`, { html: await selfContainedHtml() }, { auth: false });
    } catch (e) {
      if (!(e instanceof ApiError) || ![401, 403, 409].includes(e.status)) message.textContent = `The printed page was not stored: ${e.message}`;
      return;
    }
  }
  const link = document.getElementById('stored-page');
  link.href = `/api/certificates/${encodeURIComponent(record.number)}/page`;
  link.title = `The page as first printed, stored ${dateTime(page.stored)} by ${page.stored_by}; SHA-256 ${page.sha256}`;
  link.dataset.sha256 = page.sha256;
  link.hidden = false;
}

// The page as one self-contained file: styles inlined, no scripts, no toolbar.
async function selfContainedHtml() {
  const css = await (await fetch('css/certificate.css')).text();
  const doc = document.documentElement.cloneNode(true);
  for (const el of doc.querySelectorAll('script, link[rel="stylesheet"], .no-print')) el.remove();
  const style = document.createElement('style');
  style.textContent = css;
  doc.querySelector('head').append(style);
  return `<!doctype html>\n${doc.outerHTML}\n`;
}

function coefficientTable(rows, judged) {
  const head = ['Coefficient', 'Estimate', 'u (k = 1)', `U (k = ${COVERAGE_K})`, 'Unit', ...(judged ? ['Limit', 'Result'] : [])];
  const body = h('tbody');
  for (const r of rows) {
    const name = h('td', { class: 'name' }, r.name, ' ', h('span', { class: 'key' }, r.collapsed ? `${r.key}.*` : r.key));
    // What the run did not estimate is said once across the three number columns.
    // Rounded as certificates round (roundedNumbers); what the run did not estimate is said once
    // across the three number columns, a noise term's missing uncertainty once across two.
    const n = roundedNumbers(r);
    const numbers = !r.determined
      ? [h('td', { class: 'nd', colspan: 3 }, r.collapsed ? `${NOT_DETERMINED} (all ${r.count})` : NOT_DETERMINED)]
      : n.u === null ? [h('td', { class: 'num' }, n.value), h('td', { class: 'nd', colspan: 2 }, 'no uncertainty (noise term)')]
        : [h('td', { class: 'num' }, n.value), h('td', { class: 'num' }, n.u), h('td', { class: 'num' }, n.U)];
    const tr = h('tr', { dataset: { key: r.key }, class: r.pass === false ? 'fail' : null }, name, ...numbers, h('td', {}, r.unit));
    if (judged) {
      // Each limit on one line at most: a wrap comes only between the value's and u's.
      const parts = r.limit ? r.limit.split('; ') : [];
      tr.append(h('td', { class: 'limit' }, ...parts.flatMap((t, i) => [i ? '; ' : null, h('span', {}, t)])),
        h('td', { class: `result ${r.pass === null ? '' : r.pass ? 'pass' : 'fail'}` },
          r.pass === null ? '' : r.pass ? 'pass' : `FAIL${r.reason ? `: ${r.reason}` : ''}`));
    }
    body.append(tr);
  }
  return h('table', { class: judged ? 'coefficients judged' : 'coefficients', id: 'certificate-coefficients' },
    h('thead', {}, h('tr', {}, ...head.map((t, i) => h('th', { class: i >= 1 && i <= 3 ? 'num' : null }, t)))), body);
}

// The uncertainty budget (the model's `budget`): per coefficient each source's standard
// uncertainty, their root-sum-square u and U = k u; null when the model states none.
function budgetSection(model, number) {
  const t = budgetTable(model);
  if (!t.rows.length) return null;
  const two = (v) => (typeof v === 'number' ? Number(v.toPrecision(2)).toString() : '—');
  const head = ['Coefficient', 'Unit', ...t.sources.map(sourceName), 'u (k = 1)', `U (k = ${COVERAGE_K})`];
  const body = h('tbody', {}, ...t.rows.map((r) => h('tr', { dataset: { key: r.key } },
    h('td', { class: 'name' }, coefficientName(r.key)), h('td', {}, unitOf(r.key)),
    ...t.sources.map((s) => h('td', { class: `num${s === r.dominant ? ' dominant' : ''}`, dataset: { source: s } },
      s in r.contributions ? two(r.contributions[s]) : '')),
    h('td', { class: 'num' }, two(r.u)), h('td', { class: 'num' }, r.u === null ? '—' : two(COVERAGE_K * r.u)))));
  return h('section', { class: 'annex', id: 'certificate-annex' },
    h('h2', { class: 'budget-head' }, `Annex to certificate ${number}: uncertainty budget`),
    h('p', { class: 'small' }, 'Each source\'s standard uncertainty (k = 1) per coefficient, in the coefficient\'s unit, ' +
      'computed from its sensitivity; u is their root-sum-square. The largest of each row is marked.'),
    h('table', { class: 'coefficients budget', id: 'certificate-budget' },
      h('thead', {}, h('tr', {}, ...head.map((x, i) => h('th', { class: i >= 2 ? 'num' : null }, x)))), body));
}

function factsTable(facts) {
  const body = h('tbody');
  const cells = ([k, v], span) => [h('th', {}, k), h('td', { dataset: { fact: k }, colspan: span }, v)];
  for (let i = 0; i < facts.length; i++) {
    const [, , cls, wide] = facts[i];
    const next = facts[i + 1];
    if (!wide && next && !next[3]) {
      body.append(h('tr', { class: cls }, ...cells(facts[i]), ...cells(next)));
      i++;
    } else {
      body.append(h('tr', { class: cls }, ...cells(facts[i], 3)));
    }
  }
  return h('table', { class: 'facts' }, body);
}

// What supersedes what, and how to check a download of it: the signed JSON, its content's SHA-256,
// the lab key's fingerprint and the command that checks them offline.
function issueNotes(record) {
  const notes = [];
  if (record.superseded_by) {
    notes.push(h('p', { class: 'superseded-note', id: 'certificate-superseded' },
      `SUPERSEDED by certificate ${record.superseded_by}: this certificate no longer states the current result.`));
  }
  // Said by imucald on reading (not part of the issued content): the site's g was corrected since.
  if (record.gravity_corrected) {
    notes.push(h('p', { class: 'superseded-note', id: 'certificate-gravity-corrected' }, record.gravity_corrected.text));
  }
  if (record.supersedes) notes.push(h('p', { class: 'small', id: 'certificate-supersedes' }, `Supersedes certificate ${record.supersedes} (${record.reason}).`));
  return notes;
}

function verification(record) {
  const fp = record.signed?.signature?.key_fingerprint;
  return h('p', { class: 'small verification', id: 'certificate-verification' },
    `Content SHA-256 ${record.content_sha256}. `,
    fp ? `Signed with the lab's key ${fp}: check a download of the signed JSON with ` : 'Not signed (the lab has configured no key). ',
    fp ? h('code', {}, `imucal verify certificate-${record.number}.json --fingerprint ${fp}`) : null, fp ? '.' : null);
}

function render(d, model, status, cert, record) {
  const number = cert.number;
  const site = status.site || {};
  // The serial the run file records (GET /api/campaigns/{id}: imu_serial): the campaign's unit's
  // when it names one.
  const serial = d.imu_serial || d.imu?.serial || null;
  const unit = d.imu || {};
  document.title = `Calibration certificate ${number}`;
  const rows = certificateRows(model, d.verdict);
  const verdict = verdictStatement(d.verdict, unit.part_number);
  const partial = partialStatement(d);
  const equipment = equipmentLines(cert);
  const override = overrideStatement(d);
  // [label, text, class, wide]: short facts share a line two by two, wide ones take a line.
  const facts = [
    ['IMU serial number', serial || 'not recorded (the campaign was never started)'],
    ...[['Part number', unit.part_number], ['Firmware', unit.firmware], ['Customer', unit.customer]].filter(([, v]) => v),
    ['Date of calibration', `${dateTime(d.started)} – ${dateTime(d.ended)} (local time)`, null, true],
    ['Date of issue', dateTime(cert.issued)],
    ['Final state', d.state + (d.error ? ` (${d.error})` : '')],
    ['Site', `${site.name || '—'}; latitude ${num(site.latitude_deg, 6)}°, longitude ${num(site.longitude_deg, 6)}°, height ${num(site.height_m, 4)} m; table azimuth ${num(site.middle_axis_azimuth_deg, 4)}°`, null, true],
    ['Gravity', gravityStatement(cert.gravity), null, true],
    ...equipment.map((e) => [e.role, e.text, e.overdue ? 'overdue' : e.missing ? 'missing' : null, true]),
    // Beside the equipment it concerns: the operator's override of an overdue instrument.
    ...(override ? [['Overdue equipment overridden', override, 'overdue', true]] : []),
    ['Campaign', `${d.id} "${d.name}", ${d.program}, ${d.frames ?? '—'} frames (${d.lost_frames ?? 0} lost, ${d.bad_frames ?? 0} bad)`, null, true],
    ['Chamber', d.spec?.chamber ? `${d.spec.chamber.setpoint_C} °C ± ${d.spec.chamber.tolerance_C} °C${d.spec.chamber.steps?.length ? `, ${d.spec.chamber.steps.length} set-point steps` : ''}` : '—'],
    ['Method', `${(d.spec?.estimators || []).join(', ') || '—'} estimation, three-axis rate table; imucald ${status.version || ''}, ${model.format || ''}, ${model.frame || 'instrument'} frame`, null, true],
  ];
  const badges = h('div', { class: 'badges' },
    verdict.status ? h('span', { class: `badge ${verdict.status.toLowerCase()}`, id: 'certificate-verdict' }, verdict.status) : null,
    partial ? h('span', { class: 'badge partial', id: 'certificate-partial' }, 'PARTIAL') : null);
  fill(sheet,
    cert.simulated ? h('div', { class: 'watermark', 'aria-hidden': 'true' }, 'SIMULATION') : null,
    h('header', {}, h('h1', {}, 'Calibration certificate'),
      h('div', { class: 'title-right' }, h('p', { class: 'number', id: 'certificate-number' }, number), badges)),
    h('div', { class: 'title-block' },
      partial ? h('p', { class: 'partial-note', id: 'certificate-partial-reason' }, `Partial run: ${partial}.`) : null,
      h('p', { class: `verdict-note ${verdict.status ? verdict.status.toLowerCase() : 'none'}`, id: 'certificate-verdict-text' },
        verdict.status ? `${verdict.status}: ${verdict.text}` : verdict.text)),
    ...issueNotes(record),
    cert.simulated ? h('p', { class: 'sim-note' }, 'Made with simulated devices: this documents a simulation, not a physical instrument.') : null,
    factsTable(facts),
    h('h2', {}, 'Coefficients'),
    h('p', { class: 'small', id: 'certificate-uncertainty' }, UNCERTAINTY_TEXT),
    coefficientTable(rows, Boolean(d.verdict)),
    h('h2', {}, 'Conventions'),
    h('div', { class: 'conventions', id: 'certificate-conventions' }, ...conventionsText(model.frame).map((t) => h('p', {}, t))),
    h('div', { class: 'signatures' },
      h('div', {}, h('span', { class: 'line' }), 'Operator'), h('div', {}, h('span', { class: 'line' }), 'Checked by'), h('div', {}, h('span', { class: 'line' }), 'Date')),
    verification(record),
    h('footer', {}, `Certificate ${number}, issued ${dateTime(cert.issued)} by imucal for campaign ${d.id}; printed ${dateTime(new Date().toISOString())}. The model JSON of this campaign is the authoritative form of these coefficients.` +
      (model.budget ? ' The uncertainty budget behind u is its annex (and in the signed JSON).' : '')),
    // The budget behind u: an annex, printed on a page of its own when asked for.
    budgetSection(model, number));
  sheet.dataset.ready = 'true';
}

// The signed envelope (imucal-signed/1) as issued, for `imucal verify`; the record when unsigned.
function saveJson() {
  if (!issued) return;
  const text = `${JSON.stringify(issued.signed || issued, null, 1)}\n`;
  const url = URL.createObjectURL(new Blob([text], { type: 'application/json' }));
  const a = h('a', { href: url, download: `certificate-${issued.number}.json` });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
  message.textContent = issued.signed ? 'Saved the signed certificate.' : 'Saved (not signed: the lab has no key configured).';
}

async function saveHtml() {
  try {
    const html = await selfContainedHtml();
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
