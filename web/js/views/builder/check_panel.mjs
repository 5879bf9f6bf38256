// The builder's check: imucald's verdict on the campaign (or the page's own, before anything is
// sent), each problem beside its segment or field and the rest listed, each segment's program
// time, the Create buttons (an operator's, once the campaign is valid) and the JSON sent.
import { h, clear, duration, num } from '../../format.mjs';
import { isOperator } from '../../session.mjs';
import { mapProblems, sourceIndex, compress, problemForPeople } from '../../program_edit.mjs';

/** The side panel's part: nodes to lay out; render() shows state.validation, updateRoleUi()
 *  the buttons for who is signed in, showJson(body), say(text) imucald's message.
 *  onInvalid() when the campaign is invalid; onSubmit(andStart) on a Create button. */
export function checkPanel(root, state, { onInvalid, onSubmit }) {
  const verdict = h('div', { class: 'verdict', id: 'verdict', 'aria-live': 'polite' });
  const problemsList = h('ul', { class: 'problems', id: 'problems' });
  const serverMessage = h('div', { class: 'form-error', role: 'alert', id: 'server-message' });
  const preview = h('pre', { class: 'json-preview', id: 'json-preview' });
  const createButton = h('button', { type: 'button', id: 'create', class: 'operator-only' }, 'Create campaign');
  const startButton = h('button', { type: 'button', id: 'create-start', class: 'primary operator-only' }, 'Create and start…');
  const viewerNote = h('p', { class: 'hint viewer-only' }, 'You are signed in as a viewer: you can build and check a campaign, but only an operator can create or start one.');
  createButton.addEventListener('click', () => onSubmit(false));
  startButton.addEventListener('click', () => onSubmit(true));

  function render() {
    const v = state.validation;
    verdict.dataset.state = v.state;
    const scale = state.draft.campaign.time_scale;
    const wall = v.duration_s && scale > 0 ? v.duration_s / scale : null;
    const texts = {
      idle: 'Not checked yet.',
      local: 'Fix the marked fields; nothing is sent until they are valid.',
      checking: 'Checking with imucald…',
      valid: `Valid: ${v.segments.length} segments, ${duration(v.duration_s)} of program${wall ? `, about ${duration(wall)} at ×${num(scale, 3)}` : ''}.`,
      invalid: `Refused: ${v.problems.length} problem${v.problems.length === 1 ? '' : 's'}${v.duration_s ? `; program ${duration(v.duration_s)}` : ''}.`,
      error: 'The check failed.',
    };
    verdict.textContent = texts[v.state] || v.state;
    if (v.state === 'local' || v.state === 'invalid') onInvalid();
    // Inline: each problem beside its segment or field; the rest in the side panel.
    for (const ul of root.querySelectorAll('.segment-problems')) clear(ul);
    for (const tr of root.querySelectorAll('tr.segment')) tr.classList.remove('has-problems');
    for (const el of root.querySelectorAll('[data-field]')) el.classList.remove('has-problems');
    for (const el of root.querySelectorAll('.server-field-problem')) el.remove();
    clear(problemsList);
    if (v.state === 'local') {
      for (const p of v.problems) problemsList.append(h('li', {}, p));
    } else if (v.state === 'invalid' || v.state === 'error') {
      const mapped = mapProblems(v.problems, state.draft.program.segments);
      for (const [i, list] of mapped.bySegment) {
        const ul = root.querySelector(`#seg-${i}-problems`);
        root.querySelector(`#segment-${i}`)?.classList.add('has-problems');
        for (const p of compress(list)) ul?.append(h('li', { class: 'problem' }, p.replace(/^campaign\.program: /, '')));
      }
      for (const [path, list] of mapped.byField) {
        const host = root.querySelector(`[data-field="${CSS.escape(path)}"]`) || root.querySelector(`[data-field="${CSS.escape(path.split(/[.[]/)[0])}"]`);
        if (!host) { mapped.general.push(...list); continue; }
        host.classList.add('has-problems');
        host.append(h('div', { class: 'server-field-problem problem' }, list.map(problemForPeople).join('; ')));
      }
      for (const p of compress(v.problems)) problemsList.append(h('li', { class: 'problem' }, problemForPeople(p)));
    }
    renderTimes(v.segments);
    updateRoleUi();
  }

  // Program time of each source segment, from the compiled segments the daemon returned.
  function renderTimes(compiled) {
    const segments = state.draft.program.segments;
    segments.forEach((s, i) => {
      const cell = root.querySelector(`#seg-${i}-time`);
      if (cell) cell.textContent = '';
    });
    const spans = new Map();
    for (const c of compiled) {
      const i = sourceIndex(c.name, segments);
      if (i < 0) continue;
      const s = spans.get(i) || { t0: Infinity, t1: -Infinity };
      s.t0 = Math.min(s.t0, c.t0_s);
      s.t1 = Math.max(s.t1, c.t1_s);
      spans.set(i, s);
    }
    for (const [i, s] of spans) {
      const cell = root.querySelector(`#seg-${i}-time`);
      if (cell) cell.textContent = `${s.t0.toFixed(0)}–${s.t1.toFixed(0)} s`;
    }
  }

  function updateRoleUi() {
    const operator = isOperator();
    const validation = state.validation;
    // A campaign imucald's check refused would only be refused again (422): fix it first.
    const blocked = validation.state === 'local' || validation.state === 'checking' || validation.state === 'invalid';
    for (const b of [createButton, startButton]) {
      b.disabled = !operator || blocked;
      b.title = !operator ? 'operator role required'
        : validation.state === 'invalid' ? 'imucald refused this campaign: fix the problems listed'
          : blocked ? 'wait for the check, or fix the marked fields' : '';
    }
    viewerNote.hidden = operator;
  }

  return {
    nodes: [h('h2', {}, 'Check'), verdict, problemsList, serverMessage, viewerNote,
      h('div', { class: 'actions' }, createButton, startButton),
      h('details', {}, h('summary', {}, 'JSON sent to imucald'), preview)],
    render, updateRoleUi,
    showJson: (body) => { preview.textContent = JSON.stringify(body, null, 1).slice(0, 20000); },
    say: (text) => { serverMessage.textContent = text; },
    disableButtons: () => { createButton.disabled = startButton.disabled = true; },
  };
}
