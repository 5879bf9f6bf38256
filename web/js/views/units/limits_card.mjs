// The acceptance limits per part number (GET/PUT /api/limits), which an operator edits here in a
// form, a block per part number and a row per coefficient key (limits_part.mjs, limits_form.mjs),
// or as the file itself (imucal-limits/1, docs/api.md "Units") under "Advanced".
import { api, get } from '../../api.mjs';
import { h, clear } from '../../format.mjs';
import { groups } from '../../coefficients.mjs';
import { limitsToForm, formToLimits, emptyRow, locateServerProblem } from '../../limits_form.mjs';
import { limitsPart, example } from './limits_part.mjs';

/** The card; load() reads the limits into the form; onSaved() after imucald took a save. */
export function limitsCard({ onSaved }) {
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
  const element = h('section', { class: 'card', id: 'limits-card' }, h('h2', {}, 'Acceptance limits'),
    h('p', { class: 'hint' },
      `Per part number, for each coefficient (such as ${example().key}) or group of them (${example().group}: every axis): `,
      'the largest |value| and the largest 1σ uncertainty, in the coefficient\'s unit; either may be left empty. ',
      'The most specific key applies. A run that did not determine a limited coefficient fails on it. ',
      'Operators may save; imucald checks the whole file before it replaces the old one.'),
    keyList, limitsForm,
    h('div', { class: 'actions' }, addPart, save), limitsMessage,
    h('details', { id: 'limits-advanced' }, h('summary', {}, 'Advanced: the limits file as JSON (imucal-limits/1)'),
      editor, h('div', { class: 'actions' }, useJson)));

  let form = { parts: [] };
  let showAll = false;      // after a save was tried, every problem shows, not only edited rows'
  let serverProblem = null; // {part, row, message}: imucald's refusal, until the next edit

  function message(state, text) {
    limitsMessage.dataset.state = state;
    limitsMessage.textContent = text;
  }

  async function load() {
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

  const focus = (id) => limitsForm.querySelector(`#${id}`)?.focus();
  function renderForm() {
    clear(limitsForm);
    if (!form.parts.length)
      limitsForm.append(h('p', { class: 'muted', id: 'limits-none' }, 'No limits: no run is judged. Add a part number to set some.'));
    form.parts.forEach((p, pi) => limitsForm.append(limitsPart(p, pi, {
      edited, focus, removePart: () => { form.parts.splice(pi, 1); edited(true); } })));
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
    focus(`limits-part-${form.parts.length - 1}-number`);
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
      await onSaved();
    } catch (e) {
      // imucald names the part number and key it refused: shown beside that row as well.
      const where = locateServerProblem(e.message, form);
      serverProblem = where ? { ...where, field: where.row === null ? null : 'key', message: e.message } : null;
      showProblems();
      message('error', `Not saved: ${e.message}`);
    }
  });

  return { element, load };
}
