// The units (issue 17): every IMU a campaign named (GET /api/imus) with its calibrations and the
// verdict of its last one, and the acceptance limits per part number (GET/PUT /api/limits), which
// an operator edits here as the limits file itself (imucal-limits/1, docs/api.md "Units").
import { api, get } from '../api.mjs';
import { h, clear, dateTime } from '../format.mjs';

export function verdictBadge(pass, title = '') {
  if (pass === null || pass === undefined) return h('span', { class: 'muted', title: 'No acceptance limits for this part number' }, 'no limits');
  return h('span', { class: pass ? 'result-ok verdict' : 'result-bad verdict', title }, pass ? 'PASS' : 'FAIL');
}

export function mount(root) {
  const status = h('div', { class: 'form-error', role: 'alert', id: 'units-error' });
  const body = h('tbody', { id: 'units-rows' });
  const editor = h('textarea', { id: 'limits-text', rows: 16, spellcheck: 'false', class: 'code' });
  const limitsMessage = h('p', { id: 'limits-message', role: 'status' });
  const save = h('button', { type: 'button', id: 'limits-save' }, 'Save limits');

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'Units')), status,
    h('section', { class: 'card' }, h('h2', {}, 'Units calibrated here'),
      h('table', { class: 'list', id: 'units-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'Serial'), h('th', {}, 'Part number'), h('th', { class: 'num' }, 'Campaigns'),
          h('th', { class: 'num' }, 'Calibrations'), h('th', {}, 'Last calibration'), h('th', {}, 'Verdict'))),
        body)),
    h('section', { class: 'card' }, h('h2', {}, 'Acceptance limits'),
      h('p', { class: 'hint' },
        'Per part number, for each coefficient (a flat key such as "gyro.bias_dph.x", or a group such as "gyro.bias_dph" for every axis): ',
        '"max_abs" limits |value|, "max_sigma" its 1σ uncertainty, in the key\'s unit. A run that did not determine a limited coefficient fails on it. ',
        'Operators may save; the file is checked whole before it replaces the old one.'),
      editor, h('div', { class: 'actions' }, save), limitsMessage));

  async function loadUnits() {
    try {
      const r = await get('/api/imus');
      clear(body).append(...(r.imus || []).map((u) => h('tr', { dataset: { serial: u.serial } },
        h('td', {}, h('a', { href: `#/imus/${encodeURIComponent(u.serial)}` }, u.serial)),
        h('td', {}, u.part_number || ''), h('td', { class: 'num' }, u.campaigns), h('td', { class: 'num' }, u.calibrations),
        h('td', {}, u.last_calibration ? h('a', { href: `#/campaigns/${u.last_calibration.campaign_id}` },
          `#${u.last_calibration.campaign_id} ${u.last_calibration.program}, ${dateTime(u.last_calibration.date)}`) : '—'),
        h('td', {}, u.last_calibration ? verdictBadge(u.pass) : '—'))));
      if (!(r.imus || []).length) body.append(h('tr', {}, h('td', { colspan: 6, class: 'muted' }, 'No campaign has named a unit yet.')));
    } catch (e) {
      status.textContent = `Cannot list the units: ${e.message}`;
    }
  }

  async function loadLimits() {
    try {
      const doc = await get('/api/limits');
      limitsMessage.textContent = `From ${doc.source}.`;
      delete doc.source;
      editor.value = JSON.stringify(doc, null, 2);
    } catch (e) {
      limitsMessage.textContent = `Cannot read the limits: ${e.message}`;
    }
  }

  save.addEventListener('click', async () => {
    let doc;
    try {
      doc = JSON.parse(editor.value);
    } catch (e) {
      limitsMessage.textContent = `Not saved: the text is not JSON (${e.message}).`;
      return;
    }
    try {
      await api('PUT', '/api/limits', doc);
      limitsMessage.textContent = 'Saved. Verdicts now judge by these limits.';
      await loadUnits();
    } catch (e) {
      limitsMessage.textContent = `Not saved: ${e.message}`;
    }
  });

  loadUnits();
  loadLimits();
}
