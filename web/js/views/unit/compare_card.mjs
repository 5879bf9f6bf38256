// Two of a unit's calibrations side by side (GET /api/compare): each coefficient's difference and
// whether it is significant.
import { get } from '../../api.mjs';
import { h, clear, dateTime, num } from '../../format.mjs';
import { orderOf, unitOf } from '../../coefficients.mjs';

/** The card; show(calibrations) offers those with a model, the last two picked. */
export function compareCard() {
  const pickA = h('select', { id: 'compare-a' });
  const pickB = h('select', { id: 'compare-b' });
  const compareOut = h('div', { id: 'unit-compare' });
  const element = h('section', { class: 'card' }, h('h2', {}, 'Two calibrations side by side'),
    h('div', { class: 'actions' }, h('label', { for: 'compare-a' }, 'From'), pickA, h('label', { for: 'compare-b' }, 'to'), pickB,
      h('button', { type: 'button', id: 'compare-go', onclick: () => compare() }, 'Compare')),
    h('p', { class: 'hint' }, 'A difference is significant beyond 3 combined sigmas (the two runs\' 1σ added in quadrature).'),
    compareOut);

  async function compare() {
    if (!pickA.value || !pickB.value) return;
    clear(compareOut).append(h('p', { class: 'muted' }, 'Comparing…'));
    try {
      const c = await get(`/api/compare?a=${pickA.value}&b=${pickB.value}`);
      clear(compareOut).append(
        h('p', { id: 'compare-summary' }, `${c.significant} significant difference${c.significant === 1 ? '' : 's'} between #${c.a.campaign_id} and #${c.b.campaign_id}.`),
        comparisonTable(c));
    } catch (e) {
      clear(compareOut).append(h('p', { class: 'form-error' }, `Cannot compare: ${e.message}`));
    }
  }

  function show(calibrations) {
    const withModel = calibrations.filter((c) => c.model);
    const option = (c) => h('option', { value: c.campaign_id }, `#${c.campaign_id} ${c.name} (${dateTime(c.date)})`);
    clear(pickA).append(...withModel.map(option));
    clear(pickB).append(...withModel.map(option));
    if (withModel.length >= 2) {
      pickA.value = String(withModel[withModel.length - 2].campaign_id);
      pickB.value = String(withModel[withModel.length - 1].campaign_id);
    }
  }
  return { element, show };
}

function comparisonTable(c) {
  const rows = c.coefficients.slice().sort((x, y) => orderOf(x.key) - orderOf(y.key) || x.key.localeCompare(y.key));
  const sig = (s) => (s == null ? '' : ` ± ${num(s, 2)}`);
  return h('table', { class: 'list', id: 'compare-table' },
    h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, `#${c.a.campaign_id}`), h('th', { class: 'num' }, `#${c.b.campaign_id}`),
      h('th', { class: 'num' }, 'Difference'), h('th', { class: 'num' }, 'In combined σ'), h('th', {}, 'Unit'))),
    h('tbody', {}, ...rows.map((r) => h('tr', { class: r.significant ? 'result-bad' : '', dataset: { key: r.key } },
      h('td', {}, r.key), h('td', { class: 'num' }, `${num(r.a, 5)}${sig(r.sigma_a)}`), h('td', { class: 'num' }, `${num(r.b, 5)}${sig(r.sigma_b)}`),
      h('td', { class: 'num' }, num(r.difference, 3)), h('td', { class: 'num' }, r.in_sigmas == null ? '—' : num(r.in_sigmas, 2)),
      h('td', {}, unitOf(r.key))))));
}
