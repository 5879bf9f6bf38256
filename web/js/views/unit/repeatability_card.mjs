// A unit's turn-on to turn-on repeatability (IEEE Std 952) as imucald computed it.
import { h, clear, num } from '../../format.mjs';
import { orderOf, unitOf } from '../../coefficients.mjs';

/** The card; show(repeatability) fills its table (coefficient -> {n, mean, std}). */
export function repeatabilityCard() {
  const body = h('tbody', { id: 'unit-repeatability' });
  const element = h('section', { class: 'card' }, h('h2', {}, 'Repeatability'),
    h('p', { class: 'hint' }, 'Turn-on to turn-on (IEEE Std 952): the sample standard deviation of each coefficient over the calibrations that count and determined it.'),
    h('table', { class: 'list' }, h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, 'Runs'),
      h('th', { class: 'num' }, 'Mean'), h('th', { class: 'num' }, 'Standard deviation'), h('th', {}, 'Unit'))), body));
  function show(repeatability) {
    const rep = Object.entries(repeatability || {}).sort(([a], [b]) => orderOf(a) - orderOf(b) || a.localeCompare(b));
    clear(body).append(...rep.map(([k, r]) => h('tr', { dataset: { key: k } }, h('td', {}, k), h('td', { class: 'num' }, r.n),
      h('td', { class: 'num' }, num(r.mean, 5)), h('td', { class: 'num' }, num(r.std, 3)), h('td', {}, unitOf(k)))));
    if (!rep.length) body.append(h('tr', {}, h('td', { colspan: 5, class: 'muted' }, 'Needs two calibrations that count.')));
  }
  return { element, show };
}
