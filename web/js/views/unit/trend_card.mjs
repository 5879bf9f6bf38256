// A chosen coefficient over a unit's calibrations with a model, oldest first, as a trend with its
// ±1 sigma band.
import { h, clear } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';
import { flatten, orderOf, unitOf } from '../../coefficients.mjs';

/** The card; show(calibrations) offers their coefficients and plots the first; destroy() drops the chart. */
export function trendCard() {
  const select = h('select', { id: 'unit-coefficient' });
  const plotBox = h('div', { class: 'plot', id: 'unit-trend' });
  const element = h('section', { class: 'card' }, h('h2', {}, 'Trend'),
    h('div', { class: 'actions' }, h('label', { for: 'unit-coefficient' }, 'Coefficient'), select),
    h('p', { class: 'hint' }, 'Each calibration with a model, oldest first; the band is ±1 sigma.'), plotBox);
  let chart = null;
  let calibrations = [];

  function plot(name) {
    const points = calibrations.filter((c) => c.model);
    const values = points.map((c) => flatten(c.model).get(name) ?? null);
    const sigmas = points.map((c) => (c.model.sigma ? flatten(c.model.sigma).get(name) ?? null : null));
    const hi = values.map((v, i) => (v == null || sigmas[i] == null ? null : v + sigmas[i]));
    const lo = values.map((v, i) => (v == null || sigmas[i] == null ? null : v - sigmas[i]));
    if (chart) chart.destroy();
    clear(plotBox);
    chart = lineChart(plotBox, { title: `${name} [${unitOf(name)}]`, x: 'calibration', xIntegers: true, y: unitOf(name), height: 220, points: true,
      series: [{ label: 'value', color: COLORS[0] }, { label: '+1σ', band: true }, { label: '−1σ', band: true }],
      bands: [[2, 3, 'rgba(21,101,192,0.15)']] });
    chart.setData([points.map((_, i) => i + 1), values, hi, lo]);
  }
  select.addEventListener('change', () => plot(select.value));

  function show(list) {
    calibrations = list;
    const names = new Set();
    for (const c of calibrations) if (c.model) for (const n of flatten(c.model).keys()) names.add(n);
    const sorted = [...names].sort((a, b) => orderOf(a) - orderOf(b) || a.localeCompare(b));
    clear(select).append(...sorted.map((n) => h('option', { value: n }, `${n} [${unitOf(n)}]`)));
    if (sorted.length) plot(sorted[0]);
  }
  return { element, show, destroy: () => { if (chart) chart.destroy(); } };
}
