// Confirmation before anything that moves the table or throws work away, and the command buttons
// (start, pause, resume, stop, abort) shared by the campaign page and the live view.
import { h, allowedCommands } from './format.mjs';
import { post } from './api.mjs';
import { isOperator } from './session.mjs';

/**
 * A modal question. Resolves {ok, reason}. `reason: true` offers a free-text reason that the
 * daemon stores with the transition.
 */
export function confirmDialog({ title, body, confirmLabel = 'OK', danger = false, reason = false }) {
  return new Promise((resolve) => {
    const reasonInput = reason ? h('input', { type: 'text', id: 'confirm-reason', maxlength: 500, placeholder: 'optional, kept with the campaign' }) : null;
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
      const r = await post(`/api/campaigns/${c.id}/${name}`, reason ? { reason } : {});
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
