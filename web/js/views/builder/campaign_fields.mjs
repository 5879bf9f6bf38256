// The builder's campaign card: the campaign's name, estimators, frame rate, time scale, seed and
// the simulated IMU's truth (truth_field.mjs).
import { h, clear } from '../../format.mjs';
import { parseNumber, campaignFieldLabel } from '../../program_edit.mjs';
import { input, fieldRow } from './form.mjs';
import { truthField } from './truth_field.mjs';

/** The fields' box; render() draws them from state.draft. form: setError(el, message),
 *  changed() after an edit. */
export function campaignFields(state, form) {
  const campaignBox = h('div', { class: 'grid-form', id: 'campaign-fields' });

  function setCampaign(key, value, error, el) {
    if (!error) {
      if (value === undefined) delete state.draft.campaign[key]; else state.draft.campaign[key] = value;
    }
    form.setError(el, error);
    form.changed();
  }

  function render() {
    const c = state.draft.campaign;
    const limits = state.limits;
    clear(campaignBox);
    const name = input('c-name', 'name', c.name, { type: 'text', maxlength: 200, required: true });
    name.addEventListener('input', () => { setCampaign('name', name.value, name.value.trim() ? null : 'A campaign needs a name.', name); });
    const known = limits?.campaign?.estimators || ['direct', 'navigation'];
    const est = h('div', { class: 'checks', id: 'c-estimators', dataset: { path: 'estimators' } },
      ...known.map((e) => {
        const cb = h('input', { type: 'checkbox', id: `c-est-${e}`, value: e, checked: c.estimators.includes(e) });
        cb.addEventListener('change', () => {
          c.estimators = known.filter((k) => campaignBox.querySelector(`#c-est-${k}`).checked);
          form.changed();
        });
        return h('label', { class: 'check' }, cb, ` ${e}`);
      }));
    const numberInput = (id, key, hint, check) => {
      const el = input(id, key, c[key], { type: 'text', inputmode: 'decimal', class: 'short' });
      el.addEventListener('input', () => {
        const r = parseNumber(el.value);
        let err = r.error || (r.empty ? null : check?.(r.value));
        setCampaign(key, r.empty ? undefined : r.value, err, el);
      });
      return fieldRow(campaignFieldLabel(key), el, key, hint);
    };
    const maxRate = limits?.campaign?.max_rate_hz;
    campaignBox.append(
      fieldRow(campaignFieldLabel('name'), name, 'name'),
      h('div', { class: 'field', dataset: { field: 'estimators' } }, h('label', {}, 'estimators'), est,
        h('div', { class: 'field-error', id: 'c-estimators-error', role: 'alert' })),
      numberInput('c-rate', 'rate_hz', maxRate ? `IMU frames per second, ≤ ${maxRate}` : 'IMU frames per second',
        (v) => (v > 0 ? null : 'must be greater than 0')),
      numberInput('c-time-scale', 'time_scale', 'program seconds per wall second (simulation; 0: as fast as possible)',
        (v) => (v >= 0 ? null : 'must not be negative')),
      numberInput('c-seed', 'seed', 'simulation noise seed', (v) => (Number.isInteger(v) && v >= 0 ? null : 'a whole number ≥ 0')),
      truthField(c, state, { setCampaign, setError: form.setError }));
  }
  return { element: campaignBox, render };
}
