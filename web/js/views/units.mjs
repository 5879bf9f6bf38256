// The units (issue 17): every IMU a campaign named (GET /api/imus) with its calibrations and the
// verdict of its last one, and the acceptance limits per part number (GET/PUT /api/limits), which
// an operator edits here in a form, a row per coefficient key (limits_form.mjs), or as the file
// itself (imucal-limits/1, docs/api.md "Units") under "Advanced".
import { api, get } from '../api.mjs';
import { h, clear, dateTime } from '../format.mjs';
import { groups, coefficientName, unitOf } from '../coefficients.mjs';
import { schema } from '../schema.mjs';
import { limitsToForm, formToLimits, emptyRow, locateServerProblem } from '../limits_form.mjs';
import { verdictBadge } from '../components/verdict_badge.mjs';

// The example the hint and an empty key show: imucald's first coefficient, and its group.
function example() {
  return schema().coefficients[0] || { key: '', group: '' };
}

export function mount(root) {
  const status = h('div', { class: 'form-error', role: 'alert', id: 'units-error' });
  const body = h('tbody', { id: 'units-rows' });
  const limitsForm = h('div', { id: 'limits-form' });
  const limitsMessage = h('p', { id: 'limits-message', class: 'form-message', role: 'status' });
  const save = h('button', { type: 'button', id: 'limits-save', class: 'primary operator-only' }, 'Save limits');
  const addPart = h('button', { type: 'button', id: 'limits-add-part' }, 'Add a part number');
  // The file itself, for what the form does not show (pasting a whole file from elsewhere).
  const editor = h('textarea', { id: 'limits-text', rows: 14, spellcheck: 'false', class: 'code limits-json' });
  const useJson = h('button', { type: 'button', id: 'limits-json-apply' }, 'Put this JSON into the form');
  // Suggestions for a key: the coefficient groups the results name (coefficients.mjs), each also
  // a whole group; imucald judges any other name when the limits are saved.
  const keyList = h('datalist', { id: 'limit-keys' }, ...groups().map((g) => h('option', { value: g.key }, g.title)));

  let form = { parts: [] };
  let showAll = false;      // after a save was tried, every problem shows, not only edited rows'
  let serverProblem = null; // {part, row, message}: imucald's refusal, until the next edit

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'Units')), status,
    h('section', { class: 'card' }, h('h2', {}, 'Units calibrated here'),
      h('table', { class: 'list', id: 'units-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'Serial'), h('th', {}, 'Part number'), h('th', { class: 'num' }, 'Campaigns'),
          h('th', { class: 'num' }, 'Calibrations'), h('th', {}, 'Last calibration'), h('th', {}, 'Verdict'))),
        body)),
    h('section', { class: 'card', id: 'limits-card' }, h('h2', {}, 'Acceptance limits'),
      h('p', { class: 'hint' },
        `Per part number, for each coefficient (such as ${example().key}) or group of them (${example().group}: every axis): `,
        'the largest |value| and the largest 1σ uncertainty, in the coefficient\'s unit; either may be left empty. ',
        'The most specific key applies. A run that did not determine a limited coefficient fails on it. ',
        'Operators may save; imucald checks the whole file before it replaces the old one.'),
      keyList, limitsForm,
      h('div', { class: 'actions' }, addPart, save), limitsMessage,
      h('details', { id: 'limits-advanced' }, h('summary', {}, 'Advanced: the limits file as JSON (imucal-limits/1)'),
        editor, h('div', { class: 'actions' }, useJson))));

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

  function message(state, text) {
    limitsMessage.dataset.state = state;
    limitsMessage.textContent = text;
  }

  async function loadLimits() {
    try {
      const doc = await get('/api/limits');
      message('info', `From ${doc.source}.`);
      delete doc.source;
      form = limitsToForm(doc);
      showAll = false;
      serverProblem = null;
      renderForm();
    } catch (e) {
      message('error', `Cannot read the limits: ${e.message}`);
    }
  }

  // ---- the form ----

  // A coefficient key's name and unit for people, or what is wrong with it (coefficients.mjs).
  function describeKey(key) {
    const k = key.trim();
    if (!k) return '';
    const unit = unitOf(k);
    const group = groups().find((g) => g.key === k);
    const name = group ? `${group.title}, every axis` : coefficientName(k);
    return `${name === k ? '' : name}${unit ? `${name === k ? '' : ', '}in ${unit}` : ''}`;
  }

  function renderForm() {
    clear(limitsForm);
    if (!form.parts.length)
      limitsForm.append(h('p', { class: 'muted', id: 'limits-none' }, 'No limits: no run is judged. Add a part number to set some.'));
    form.parts.forEach((p, pi) => {
      const partInput = h('input', { type: 'text', id: `limits-part-${pi}-number`, value: p.partNumber, class: 'part-number', 'aria-label': 'part number' });
      partInput.addEventListener('input', () => { p.partNumber = partInput.value; p.touched = true; edited(); });
      const rows = h('tbody', {});
      p.rows.forEach((r, ri) => {
        const id = `limits-${pi}-${ri}`;
        const key = h('input', { type: 'text', id: `${id}-key`, value: r.key, list: 'limit-keys', class: 'limit-key', 'aria-label': 'coefficient or group', placeholder: `e.g. ${example().key}` });
        const name = h('span', { class: 'hint limit-name', id: `${id}-name` }, describeKey(r.key));
        const bound = (field, label) => {
          const el = h('input', { type: 'text', inputmode: 'decimal', id: `${id}-${field}`, value: r[field], class: 'short', 'aria-label': label });
          el.addEventListener('input', () => { r[field] = el.value; r.touched = true; edited(); });
          return el;
        };
        key.addEventListener('input', () => { r.key = key.value; r.touched = true; name.textContent = describeKey(r.key); edited(); });
        const remove = h('button', { type: 'button', class: 'icon danger-text', id: `${id}-remove`, title: 'Remove this limit', 'aria-label': 'remove this limit' }, '×');
        remove.addEventListener('click', () => { p.rows.splice(ri, 1); p.touched = true; edited(true); });
        rows.append(h('tr', { class: 'limit-row', id, dataset: { key: r.key } },
          h('td', {}, key, name), h('td', {}, bound('maxAbs', 'largest |value|')), h('td', {}, bound('maxSigma', 'largest 1σ')),
          h('td', { class: 'row-actions' }, remove)),
        h('tr', { class: 'limit-problems' }, h('td', { colspan: 4 }, h('ul', { class: 'segment-problems', id: `${id}-error`, role: 'alert' }))));
      });
      const add = h('button', { type: 'button', id: `limits-part-${pi}-add` }, 'Add a limit');
      add.addEventListener('click', () => { p.rows.push(emptyRow()); edited(true); root.querySelector(`#limits-${pi}-${p.rows.length - 1}-key`)?.focus(); });
      const removePart = h('button', { type: 'button', class: 'danger-text', id: `limits-part-${pi}-remove` }, 'Remove part number');
      removePart.addEventListener('click', () => { form.parts.splice(pi, 1); edited(true); });
      limitsForm.append(h('fieldset', { class: 'limits-part', id: `limits-part-${pi}` },
        h('div', { class: 'limits-part-head' }, h('label', { for: partInput.id }, 'Part number'), partInput, h('span', { class: 'spacer' }), removePart),
        h('ul', { class: 'segment-problems', id: `limits-part-${pi}-error`, role: 'alert' }),
        h('table', { class: 'list compact limits-table' },
          h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient or group'), h('th', {}, 'Largest |value|'), h('th', {}, 'Largest 1σ'), h('th', {}))),
          rows),
        p.rows.length ? null : h('p', { class: 'muted' }, 'No limits for this part number yet.'),
        h('div', { class: 'actions' }, add)));
    });
    showProblems();
  }

  // The problems the page sees (and imucald's last refusal) beside the inputs they are about.
  function showProblems() {
    const { doc, problems } = formToLimits(form);
    for (const el of limitsForm.querySelectorAll('[aria-invalid]')) el.removeAttribute('aria-invalid');
    for (const el of limitsForm.querySelectorAll('.has-problems')) el.classList.remove('has-problems');
    for (const ul of limitsForm.querySelectorAll('ul.segment-problems')) clear(ul);
    const shown = problems.filter((q) => showAll || (q.row === null ? form.parts[q.part]?.touched : form.parts[q.part]?.rows[q.row]?.touched));
    if (serverProblem) shown.push(serverProblem);
    for (const q of shown) {
      const id = q.row === null || q.row === undefined ? `limits-part-${q.part}` : `limits-${q.part}-${q.row}`;
      limitsForm.querySelector(`#${id}-error`)?.append(h('li', { class: 'problem' }, q.message));
      limitsForm.querySelector(`#${id}`)?.classList.add('has-problems');
      const input = q.field && limitsForm.querySelector(`#${id}-${q.field === 'partNumber' ? 'number' : q.field}`);
      input?.setAttribute('aria-invalid', 'true');
    }
    if (doc) editor.value = JSON.stringify(doc, null, 2);
    return { doc, problems };
  }

  function edited(structural = false) {
    serverProblem = null;
    message('info', 'Edited: not saved yet.');
    if (structural) renderForm();
    else showProblems();
  }

  addPart.addEventListener('click', () => {
    form.parts.push({ partNumber: '', rows: [emptyRow()] });
    edited(true);
    root.querySelector(`#limits-part-${form.parts.length - 1}-number`)?.focus();
  });

  useJson.addEventListener('click', () => {
    let doc;
    try {
      doc = JSON.parse(editor.value);
    } catch (e) {
      message('error', `The JSON cannot be read (${e.message}); the form is unchanged.`);
      return;
    }
    form = limitsToForm(doc);
    showAll = true;
    serverProblem = null;
    renderForm();
    message('info', 'The JSON is in the form: not saved yet.');
  });

  save.addEventListener('click', async () => {
    showAll = true;
    const { doc, problems } = showProblems();
    if (!doc) {
      message('error', `Not saved: ${problems.length} problem${problems.length === 1 ? '' : 's'} to fix, marked in the form.`);
      return;
    }
    try {
      await api('PUT', '/api/limits', doc);
      message('ok', 'Saved. Verdicts now judge by these limits.');
      for (const p of form.parts) { p.touched = false; for (const r of p.rows) r.touched = false; }
      await loadUnits();
    } catch (e) {
      // imucald names the part number and key it refused: shown beside that row as well.
      const where = locateServerProblem(e.message, form);
      serverProblem = where ? { ...where, field: where.row === null ? null : 'key', message: e.message } : null;
      showProblems();
      message('error', `Not saved: ${e.message}`);
    }
  });

  loadUnits();
  loadLimits();
}
