// Stage 3's innovations on the live page: one small chart per measured quantity, its ±gate as a
// band, the navigation's restarts as dashed lines.
import { h, duration } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';
import { unitOf } from '../../coefficients.mjs';

/** The card, hidden until stage 3 has innovations; draw() shows the store's; destroy() drops the charts. */
export function innovationsCard(store) {
  const noteEl = h('p', { class: 'muted', id: 'innovations-note' });
  const grid = h('div', { class: 'conv-grid', id: 'innovations' });
  const element = h('section', { class: 'card', id: 'innovations-card', hidden: true },
    h('h2', {}, 'Stage 3: innovations against their gates'), noteEl, grid);
  const charts = new Map();
  // A draw scheduled for the next frame may come after the view was left (its elements gone).
  let destroyed = false;

  function draw() {
    if (destroyed) return;
    const e = store.estimators.get('stage3');
    const names = e ? [...e.innovations.keys()] : [];
    element.hidden = names.length === 0;
    if (!names.length) return;
    const latest = e.latest || {};
    const note = `${latest.updates ?? 0} updates, ${latest.rejected ?? 0} innovations rejected; ` +
      `navigation restarted ${latest.restarts ?? 0} time(s)${e.restarts.length ? ` (at ${e.restarts.map((t) => duration(t)).join(', ')})` : ''}. ` +
      'An innovation outside its gate (5 σ) is rejected.';
    if (noteEl.textContent !== note) noteEl.textContent = note;
    for (const name of names) {
      let chart = charts.get(name);
      if (!chart) {
        const box = h('div', { class: 'conv-chart', dataset: { innovation: name } });
        grid.append(box);
        chart = lineChart(box, { title: `${name}  [${unitOf(name)}]`, x: 'program s', y: unitOf(name), height: 170, legend: false,
          series: [{ label: 'innovation', color: COLORS[0] }, { label: '−gate', band: true }, { label: '+gate', band: true }],
          bands: [[3, 2, 'rgba(46,125,50,0.12)']], markers: () => store.estimators.get('stage3')?.restarts || [] });
        charts.set(name, chart);
      }
      chart.setData(e.innovations.get(name).view(Infinity, 1500));
    }
  }

  function destroy() {
    destroyed = true;
    for (const c of charts.values()) c.destroy();
  }
  return { element, draw, destroy };
}
