// Confirmation before anything that moves the table or throws work away, and the command buttons
// (start, pause, resume, stop, abort) shared by the campaign page and the live view.
import { h, allowedCommands } from './format.mjs';
import { post } from './api.mjs';
import { isOperator } from './session.mjs';
import { overdueStartQuestion } from './equipment.mjs';

/**
 * A modal question. Resolves {ok, reason}. `reason: true` offers a free-text reason that the
 * daemon stores with the transition.
 */
export function confirmDialog({ title, body, confirmLabel = 'OK', danger = false, reason = false,
  reasonPlaceholder = 'optional, kept with the campaign' }) {
  return new Promise((resolve) => {
    const reasonInput = reason ? h('input', { type: 'text', id: 'confirm-reason', maxlength: 500, placeholder: reasonPlaceholder }) : null;
    const ok = h('button', { type: 'submit', class: danger ? 'danger' : 'primary', id: 'confirm-ok' }, confirmLabel);
    const cancel = h('button', { type: 'button', id: 'confirm-cancel' }, 'Cancel');
    const form = h('form', { method: 'dialog' },
      h('h2', {}, title),
      ...(Array.isArray(body) ? body : [body]).map((b) => (typeof b === 'string' ? h('p', {}, b) : b)),
      reasonInput ? h('label', { for: 'confirm-reason' }, 'Reason') : null, reasonInput,
      h('div', { class: 'actions' }, cancel, ok));
    const dialog = h('dialog', { class: 'confirm', id: 'confirm-dialog' }, form);
    const finish = (result) => {
      dialog.close();
      dialog.remove();
      resolve(result);
    };
    cancel.addEventListener('click', () => finish({ ok: false }));
    dialog.addEventListener('cancel', (ev) => { ev.preventDefault(); finish({ ok: false }); });
    form.addEventListener('submit', (ev) => {
      ev.preventDefault();
      finish({ ok: true, reason: reasonInput ? reasonInput.value.trim() : '' });
    });
    document.body.append(dialog);
    dialog.showModal();
    cancel.focus();  // the safe choice has the focus
  });
}

/**
 * POST start. When imucald refuses it for reference equipment past its due date (409 with
 * `overdue`, docs/api.md), asks the operator whether to start anyway and why, and starts again
 * with the reason as `override_overdue`. Resolves with imucald's reply, or null when the operator
 * declined or gave no reason (`say` gets a sentence for the page); rejects with any other refusal.
 */
export async function startCampaign(id, reason, say) {
  try {
    return await post(`/api/campaigns/${id}/start`, reason ? { reason } : {});
  } catch (e) {
    const question = e.status === 409 ? overdueStartQuestion(e.body) : null;
    if (!question) throw e;
    const answer = await confirmDialog({ title: `Start campaign ${id} with overdue reference equipment?`, body: question,
      confirmLabel: 'Start anyway — the table will move', danger: true, reason: true,
      reasonPlaceholder: 'required: why the run may use it (kept in the audit trail)' });
    if (!answer.ok) {
      say?.('Not started: reference equipment is past its due date.');
      return null;
    }
    if (!answer.reason) {
      say?.('Not started: say why the campaign may start with overdue reference equipment (the reason is kept in the audit trail).');
      return null;
    }
    return post(`/api/campaigns/${id}/start`, { ...(reason ? { reason } : {}), override_overdue: answer.reason });
  }
}

const COMMANDS = {
  start: { label: 'Start', confirm: true, moves: true, cls: 'primary',
    text: (c) => [`Start campaign ${c.id} "${c.name}"?`, 'The table will move and the chamber follows the campaign\'s profile. Make sure nobody is near the table and the IMU is mounted and cabled.'] },
  pause: { label: 'Pause', confirm: false, cls: '' },
  resume: { label: 'Resume', confirm: true, moves: true, cls: 'primary',
    text: (c) => [`Resume campaign ${c.id} "${c.name}"?`, 'The table will move again: the interrupted segment is redone from its start (after homing, if the run was interrupted).'] },
  stop: { label: 'Stop', confirm: true, cls: '',
    text: (c) => [`Stop campaign ${c.id} "${c.name}" early?`, 'The table goes to rest; the estimators finish on the data recorded so far. The campaign cannot be continued afterwards.'] },
  abort: { label: 'Abort', confirm: true, danger: true, cls: 'danger',
    text: (c) => [`Abort campaign ${c.id} "${c.name}"?`, 'It ends at once: the table goes to rest with its interlock open and the chamber to its safe set point; then the estimators finish on the data so far (a partial model, which counts as a calibration only if accepted).'] },
};

/**
 * Buttons for the commands the state allows (docs/api.md run-state table). A viewer sees them
 * disabled with the reason. `getCampaign()` returns {id, name, state}; `onDone(result|error)`.
 */
export function commandBar({ getCampaign, onDone }) {
  const bar = h('div', { class: 'command-bar', role: 'group', 'aria-label': 'campaign commands' });
  const message = h('div', { class: 'form-error command-error', role: 'alert' });
  const buttons = {};
  for (const [name, spec] of Object.entries(COMMANDS)) {
    const b = h('button', { type: 'button', class: `cmd cmd-${name} ${spec.cls}`, dataset: { command: name } }, spec.label);
    b.addEventListener('click', () => run(name));
    buttons[name] = b;
    bar.append(b);
  }
  bar.append(h('span', { class: 'viewer-only muted viewer-note' }, 'read only: you are signed in as a viewer'), message);

  async function run(name) {
    const c = getCampaign();
    if (!c) return;
    const spec = COMMANDS[name];
    let reason = '';
    if (spec.confirm) {
      const answer = await confirmDialog({ title: `${spec.label} campaign ${c.id}`, body: spec.text(c),
        confirmLabel: spec.moves ? `${spec.label} — the table will move` : spec.label, danger: spec.danger, reason: true });
      if (!answer.ok) return;
      reason = answer.reason;
    }
    message.textContent = '';
    buttons[name].disabled = true;
    try {
      const r = name === 'start'
        ? await startCampaign(c.id, reason, (text) => { message.textContent = text; })
        : await post(`/api/campaigns/${c.id}/${name}`, reason ? { reason } : {});
      if (!r) return;  // not started: the operator declined the override (the message says so)
      onDone?.(name, r, null);
    } catch (e) {
      message.textContent = `${spec.label}: ${e.message}`;
      onDone?.(name, null, e);
    } finally {
      update();
    }
  }

  function update() {
    const c = getCampaign();
    const allowed = new Set(c ? allowedCommands(c.state) : []);
    const operator = isOperator();
    for (const [name, b] of Object.entries(buttons)) {
      b.hidden = !allowed.has(name);
      b.disabled = !operator;
      b.title = operator ? '' : 'operator role required (you are signed in as a viewer)';
    }
    bar.dataset.state = c ? c.state : '';
  }
  bar.update = update;
  update();
  return bar;
}
