// The units (issue 17): every IMU a campaign named (GET /api/imus) with its calibrations and the
// verdict of its last one (views/units/units_card.mjs), and the acceptance limits per part number
// (GET/PUT /api/limits), which an operator edits here in a form, a row per coefficient key
// (limits_form.mjs), or as the file itself (imucal-limits/1, docs/api.md "Units") under
// "Advanced" (views/units/limits_card.mjs).
import { h } from '../format.mjs';
import { unitsCard } from './units/units_card.mjs';
import { limitsCard } from './units/limits_card.mjs';

export function mount(root) {
  const status = h('div', { class: 'form-error', role: 'alert', id: 'units-error' });
  const units = unitsCard(status);
  // Saved limits change the verdicts: the units are read again.
  const limits = limitsCard({ onSaved: units.load });
  root.append(h('div', { class: 'page-head' }, h('h1', {}, 'Units')), status, units.element, limits.element);
  units.load();
  limits.load();
}
