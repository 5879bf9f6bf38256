// A run's verdict against its part number's acceptance limits: PASS, FAIL, or "no limits" when
// its part number has none (the units, a unit's calibrations, a campaign's results).
import { h } from '../format.mjs';

export function verdictBadge(pass, title = '') {
  if (pass === null || pass === undefined) return h('span', { class: 'muted', title: 'No acceptance limits for this part number' }, 'no limits');
  return h('span', { class: pass ? 'result-ok verdict' : 'result-bad verdict', title }, pass ? 'PASS' : 'FAIL');
}
