// The builder's chamber profile: the set point and its tolerance, then set-point steps at program
// times with their ramps.
import { h, clear } from '../../format.mjs';
import { parseNumber, campaignFieldLabel } from '../../program_edit.mjs';
import { input, fieldRow } from './form.mjs';

/** The profile's box; render() draws it from state.draft. form: setError(el, message),
 *  dropErrors(prefix), changed() after an edit. */
export function chamberFields(state, form) {
  const chamberBox = h('div', { id: 'chamber-fields' });

  function setChamber(key, value, error, el) {
    if (!error) {
      if (value === undefined) delete state.draft.campaign.chamber[key]; else state.draft.campaign.chamber[key] = value;
    }
    form.setError(el, error);
    form.changed();
  }

  function stepRow(ch, step, i) {
    const cell = (key, label) => {
      const el = input(`ch-step-${i}-${key}`, `chamber.steps[${i}].${key}`, step[key], { type: 'text', inputmode: 'decimal', class: 'short', 'aria-label': `step ${i + 1} ${label}` });
      el.addEventListener('input', () => {
        const r = parseNumber(el.value);
        let err = r.error || (r.empty ? 'required' : null);
        if (!err && key !== 'setpoint_C' && r.value < 0) err = 'must not be negative';
        if (!err) step[key] = r.value;
        form.setError(el, err);
        form.changed();
      });
      return h('td', {}, el, h('div', { class: 'field-error', id: `${el.id}-error` }));
    };
    return h('tr', { dataset: { field: `chamber.steps[${i}]` } },
      h('td', { class: 'num' }, i + 1), cell('at_s', 'at s'), cell('setpoint_C', 'set point °C'), cell('ramp_C_per_min', 'ramp °C/min'),
      h('td', {}, h('button', { type: 'button', class: 'link', 'aria-label': `remove step ${i + 1}`, onclick: () => {
        ch.steps.splice(i, 1);
        form.dropErrors('ch-step-');
        render();
        form.changed();
      } }, 'remove')));
  }

  function render() {
    const ch = state.draft.campaign.chamber || (state.draft.campaign.chamber = { steps: [] });
    clear(chamberBox);
    const lim = state.limits?.chamber;
    const sp = input('ch-setpoint', 'chamber.setpoint_C', ch.setpoint_C, { type: 'text', inputmode: 'decimal', class: 'short' });
    const tol = input('ch-tolerance', 'chamber.tolerance_C', ch.tolerance_C, { type: 'text', inputmode: 'decimal', class: 'short' });
    sp.addEventListener('input', () => {
      const r = parseNumber(sp.value);
      setChamber('setpoint_C', r.empty ? undefined : r.value, r.error, sp);
    });
    tol.addEventListener('input', () => {
      const r = parseNumber(tol.value);
      setChamber('tolerance_C', r.empty ? undefined : r.value, r.error || (r.value !== undefined && !(r.value > 0) ? 'must be greater than 0' : null), tol);
    });
    const stepsBody = h('tbody', { id: 'chamber-steps' });
    (ch.steps || []).forEach((step, i) => stepsBody.append(stepRow(ch, step, i)));
    chamberBox.append(
      h('div', { class: 'grid-form' },
        fieldRow(campaignFieldLabel('chamber.setpoint_C'), sp, 'chamber.setpoint_C', lim ? `${lim.min_C} … ${lim.max_C} °C; empty: hold the safe set point ${lim.safe_setpoint_C} °C` : ''),
        fieldRow(campaignFieldLabel('chamber.tolerance_C'), tol, 'chamber.tolerance_C', 'a reading outside set point ± tolerance suspends the run')),
      ch.steps?.length ? h('table', { class: 'steps' },
        h('thead', {}, h('tr', {}, h('th', {}, '#'), h('th', {}, 'at program time s'), h('th', {}, 'set point °C'),
          h('th', {}, `ramp °C/min (0: step${lim ? `; ≤ ${lim.max_ramp_C_per_min}` : ''})`), h('th', {}, ''))),
        stepsBody) : h('p', { class: 'hint' }, 'No set-point steps: the chamber holds the set point for the whole program.'),
      h('div', { class: 'field-error', id: 'chamber-error', dataset: { field: 'chamber' } }),
      h('button', { type: 'button', id: 'add-step', onclick: () => {
        const last = ch.steps[ch.steps.length - 1];
        ch.steps.push({ at_s: last ? last.at_s + 600 : 600, setpoint_C: (last?.setpoint_C ?? ch.setpoint_C ?? 25) + 10, ramp_C_per_min: 1 });
        render();
        form.changed();
      } }, 'Add set-point step'));
  }
  return { element: chamberBox, render };
}
