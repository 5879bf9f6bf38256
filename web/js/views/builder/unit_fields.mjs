// The unit under test (campaign.imu): its serial, offered from the serials imucald already knows
// (a known serial brings its part number), part number, firmware, customer and notes.
import { get } from '../../api.mjs';
import { h, clear } from '../../format.mjs';
import { campaignFieldLabel } from '../../program_edit.mjs';
import { input, fieldRow } from './form.mjs';

/** What is wrong with the unit's serial as typed (the daemon checks the same). */
function serialProblem(u) {
  const serial = (u.serial || '').trim();
  const others = ['part_number', 'firmware', 'customer', 'notes'].some((k) => (u[k] || '').trim());
  if (!serial) return others ? 'The unit needs a serial.' : null;
  if (serial.length > 64 || /[\/\\\u0000-\u001f\u007f]/.test(serial) || /^\.+$/.test(serial))
    return 'At most 64 printable characters, no slash, not only dots.';
  return null;
}

/** The fields' box and the known serials' list; render() draws them from state.draft,
 *  loadUnits() reads the known serials. form: setError(el, message), changed() after an edit. */
export function unitFields(state, form) {
  const unitBox = h('div', { class: 'grid-form', id: 'unit-fields' });
  const serialList = h('datalist', { id: 'known-serials' });

  // The known serials: a failure only loses the suggestions, never the builder.
  async function loadUnits() {
    try {
      const r = await get('/api/imus');
      if (state.destroyed) return;
      state.units = r.imus || [];
      clear(serialList).append(...state.units.map((u) => h('option', { value: u.serial },
        [u.part_number, `${u.calibrations} calibration${u.calibrations === 1 ? '' : 's'}`].filter(Boolean).join(', '))));
    } catch {
      state.units = [];
    }
  }

  function render() {
    const u = state.draft.campaign.imu || (state.draft.campaign.imu = {});
    clear(unitBox);
    const text = (id, key, attrs = {}) => {
      const el = input(id, `imu.${key}`, u[key], { type: 'text', maxlength: 2000, ...attrs });
      el.addEventListener('input', () => {
        u[key] = el.value;
        if (key === 'serial') {
          const known = state.units.find((x) => x.serial === el.value.trim());
          const partEl = unitBox.querySelector('#c-imu-part');
          if (known && partEl && !partEl.value.trim() && known.part_number) {
            partEl.value = known.part_number;
            u.part_number = known.part_number;
          }
        }
        form.setError(unitBox.querySelector('#c-imu-serial'), serialProblem(u));
        form.changed();
      });
      return el;
    };
    const serial = text('c-imu-serial', 'serial', { maxlength: 64, list: 'known-serials', autocomplete: 'off', placeholder: 'FOG-0042' });
    const notes = h('textarea', { id: 'c-imu-notes', dataset: { path: 'imu.notes' }, rows: 2, maxlength: 2000 });
    notes.value = u.notes || '';
    notes.addEventListener('input', () => { u.notes = notes.value; form.changed(); });
    unitBox.append(
      fieldRow(campaignFieldLabel('imu.serial'), serial, 'imu.serial', 'the unit\'s serial number; known serials are offered as you type'),
      fieldRow(campaignFieldLabel('imu.part_number'), text('c-imu-part', 'part_number'), 'imu.part_number'),
      fieldRow(campaignFieldLabel('imu.firmware'), text('c-imu-firmware', 'firmware'), 'imu.firmware'),
      fieldRow(campaignFieldLabel('imu.customer'), text('c-imu-customer', 'customer'), 'imu.customer'),
      fieldRow(campaignFieldLabel('imu.notes'), notes, 'imu.notes'));
    form.setError(serial, serialProblem(u));
  }
  return { element: unitBox, serialList, render, loadUnits };
}
