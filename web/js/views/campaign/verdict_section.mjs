import { h, num } from '../../format.mjs';
import { verdictBadge } from '../../components/verdict_badge.mjs';

// The verdict against the unit's part number's limits (GET /api/campaigns/{id}: verdict).
export function verdictSection(d) {
  const v = d.verdict;
  if (!v) {
    return h('p', { class: 'muted', id: 'acceptance-verdict' }, d.imu?.part_number
      ? `No acceptance limits for part number ${d.imu.part_number} (Units → Acceptance limits).`
      : 'The campaign names no part number: no acceptance limits apply.');
  }
  const limit = (x) => (x == null ? '—' : num(x, 3));
  return h('div', { id: 'acceptance-verdict' },
    h('h3', {}, 'Acceptance ', verdictBadge(v.pass), ` part number ${v.part_number}`),
    h('p', { class: 'muted' }, `${v.failures} of ${v.coefficients.length} limited coefficient${v.coefficients.length === 1 ? '' : 's'} fail; limits from ${v.limits}.`),
    h('table', { class: 'list', id: 'verdict-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, 'Value'), h('th', { class: 'num' }, 'σ'),
        h('th', { class: 'num' }, 'Limit |value|'), h('th', { class: 'num' }, 'Limit σ'), h('th', {}, ''), h('th', {}, 'Why'))),
      h('tbody', {}, ...v.coefficients.map((c) => h('tr', { class: c.pass ? '' : 'result-bad', dataset: { key: c.key } },
        h('td', {}, c.key), h('td', { class: 'num' }, num(c.value, 5)), h('td', { class: 'num' }, c.sigma == null ? '—' : num(c.sigma, 2)),
        h('td', { class: 'num' }, limit(c.limit_value)), h('td', { class: 'num' }, limit(c.limit_sigma)),
        h('td', {}, verdictBadge(c.pass)), h('td', {}, c.reason))))));
}
