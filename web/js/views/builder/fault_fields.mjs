// sim_faults (docs/api.md): what the simulated bench does wrong, and when, to see the
// suspenders work (a chamber offset suspends the run; it resumes by itself when it clears).
import { h, clear } from '../../format.mjs';
import { parseNumber } from '../../program_edit.mjs';
import { input } from './form.mjs';

const FAULT_KINDS = ['chamber_offset', 'imu_dropout', 'imu_corrupt', 'imu_drop', 'disconnect', 'table_fault', 'disk_full'];
const FAULT_EXTRA = { chamber_offset: { offset_C: 6 }, imu_corrupt: { frames: 10 }, imu_drop: { frames: 10 }, disconnect: { device: 'imu' } };

/** The faults' box; render() draws them from state.draft. form: setError(el, message),
 *  dropErrors(prefix), changed() after an edit. */
export function faultFields(state, form) {
  const faultsBox = h('div', { id: 'fault-fields' });

  function faultRow(faults, fault, i) {
    const numField = (key, label, required) => {
      const el = input(`fault-${i}-${key}`, `sim_faults[${i}].${key}`, fault[key], { type: 'text', inputmode: 'decimal', class: 'short', 'aria-label': `fault ${i + 1} ${label}` });
      el.addEventListener('input', () => {
        const r = parseNumber(el.value);
        let err = r.error || (r.empty && required ? 'required' : null);
        if (!err && !r.empty && key !== 'offset_C' && r.value < 0) err = 'must not be negative';
        if (!err) { if (r.empty) delete fault[key]; else fault[key] = r.value; }
        form.setError(el, err);
        form.changed();
      });
      return h('label', { class: 'param' }, h('span', {}, label), el, h('div', { class: 'field-error', id: `${el.id}-error` }));
    };
    const kind = h('select', { id: `fault-${i}-kind`, 'aria-label': `fault ${i + 1} kind` },
      ...FAULT_KINDS.map((k) => h('option', { value: k, selected: fault.kind === k }, k)));
    kind.addEventListener('change', () => {
      faults[i] = { kind: kind.value, at_s: fault.at_s, duration_s: fault.duration_s, ...FAULT_EXTRA[kind.value] };
      form.dropErrors(`fault-${i}-`);
      render();
      form.changed();
    });
    const extra = [];
    if (fault.kind === 'chamber_offset') extra.push(numField('offset_C', 'offset °C', true));
    if (fault.kind === 'imu_corrupt' || fault.kind === 'imu_drop') extra.push(numField('frames', 'frames', true));
    if (fault.kind === 'disconnect') {
      const dev = h('select', { id: `fault-${i}-device`, 'aria-label': `fault ${i + 1} device` },
        ...['table', 'chamber', 'imu'].map((d) => h('option', { value: d, selected: fault.device === d }, d)));
      dev.addEventListener('change', () => { fault.device = dev.value; form.changed(); });
      extra.push(h('label', { class: 'param' }, h('span', {}, 'device'), dev));
    }
    return h('tr', { dataset: { field: `sim_faults[${i}]` } },
      h('td', { class: 'num' }, i + 1), h('td', {}, kind),
      h('td', {}, h('div', { class: 'params' }, numField('at_s', 'at program time s', true), numField('duration_s', 'duration s', false), ...extra)),
      h('td', {}, h('button', { type: 'button', class: 'link', 'aria-label': `remove fault ${i + 1}`, onclick: () => {
        faults.splice(i, 1);
        form.dropErrors('fault-');
        render();
        form.changed();
      } }, 'remove')));
  }

  function render() {
    const faults = state.draft.campaign.sim_faults || (state.draft.campaign.sim_faults = []);
    clear(faultsBox);
    const body = h('tbody', { id: 'faults' });
    faults.forEach((fault, i) => body.append(faultRow(faults, fault, i)));
    faultsBox.append(
      faults.length ? h('table', { class: 'steps faults' }, body) : h('p', { class: 'hint' }, 'None: the simulated bench behaves. Faults apply to simulated devices only.'),
      h('button', { type: 'button', id: 'add-fault', onclick: () => {
        faults.push({ kind: 'chamber_offset', at_s: 60, duration_s: 20, offset_C: 6 });
        render();
        form.changed();
      } }, 'Add fault'));
  }
  return { element: faultsBox, render };
}
