// The simulated IMU's truth: a name imucald offers (nav-grade by default) or a model file
// uploaded from this computer, sent inline; never a path on the daemon's machine.
import { h } from '../../format.mjs';
import { truthChoices, parseTruthFile, truthLabel } from '../../truths.mjs';

// The truth select's choice that uploads a model file.
const UPLOAD = '__upload__';

/** The field for campaign c; setCampaign(key, value, error, el) takes a choice, setError(el,
 *  message) marks one missing. */
export function truthField(c, state, { setCampaign, setError }) {
  const choices = truthChoices(state.limits?.campaign?.truths);
  // A draft naming a truth imucald does not offer (kept from before): shown as it is, and
  // imucald's answer names the ones it knows.
  if (typeof c.truth === 'string' && !choices.some((t) => t.name === c.truth))
    choices.push({ name: c.truth, description: 'not offered by imucald: choose another', builtin: false });
  const truthSel = h('select', { id: 'c-truth-kind', dataset: { path: 'truth' } },
    ...choices.map((t) => h('option', { value: t.name }, t.name === 'ideal' ? 'ideal (an error-free, noise-free IMU)' : t.name)),
    h('option', { value: UPLOAD }, 'a truth JSON file from this computer…'));
  const truthFile = h('input', { id: 'c-truth-file', type: 'file', accept: '.json,application/json', 'aria-label': 'truth file', dataset: { path: 'truth' } });
  const truthNote = h('span', { class: 'hint', id: 'c-truth-description' });
  const describe = () => {
    const chosen = choices.find((t) => t.name === truthSel.value);
    truthNote.textContent = truthSel.value === UPLOAD
      ? (c.truth && typeof c.truth === 'object' ? truthLabel(c.truth) : 'Choose an imucal-imu-model/1 file (instrument frame).')
      : chosen?.description || '';
  };
  truthSel.value = typeof c.truth === 'object' && c.truth !== null ? UPLOAD : typeof c.truth === 'string' ? c.truth : 'ideal';
  truthFile.hidden = truthSel.value !== UPLOAD;
  describe();
  truthSel.addEventListener('change', () => {
    truthFile.hidden = truthSel.value !== UPLOAD;
    if (truthSel.value !== UPLOAD) setCampaign('truth', truthSel.value, null, truthFile);
    else if (!(c.truth && typeof c.truth === 'object')) setError(truthFile, 'Choose a truth file to upload.');
    describe();
  });
  truthFile.addEventListener('change', async () => {
    const file = truthFile.files?.[0];
    if (!file) return;
    const r = parseTruthFile(await file.text(), file.name);
    if (state.destroyed) return;
    setCampaign('truth', r.model, r.error || null, truthFile);
    describe();
  });
  const devices = state.devices;
  const simulatedNote = (devices || '').startsWith('sim')
    ? h('p', { class: 'muted', id: 'simulated-imu' }, `The IMU is simulated (devices: ${devices}): its errors and noise are the truth chosen here, and the results compare the calibration with it.`)
    : null;
  return h('div', { class: 'field', dataset: { field: 'truth' } }, h('label', { for: 'c-truth-kind' }, 'truth (simulated IMU)'),
    truthSel, truthFile, truthNote, h('div', { class: 'field-error', id: 'c-truth-file-error', role: 'alert' }), simulatedNote);
}
