// Estimator convergence: each coefficient's estimate with its +-sigma band over program time, as
// small multiples (one chart per coefficient, each with its own y scale, since x, y and z differ
// by orders of magnitude), one group of coefficients at a time. Used by the live view (series
// filled by the WebSocket) and the results page (series filled from /progress).
import { h, clear, num } from './format.mjs';
import { groups, groupOf, unitOf } from './coefficients.mjs';
import { lineChart, schedule, COLORS } from './plots.mjs';

const AXIS_COLOR = { x: COLORS[0], y: COLORS[1], z: COLORS[2], xy: COLORS[0], xz: COLORS[3], yx: COLORS[1], yz: COLORS[4], zx: COLORS[2], zy: COLORS[5] };

/**
 * @param {HTMLElement} el
 * @param {() => Map<string, import('./series.mjs').Series>} getSeries  coefficient -> [est, lo, hi]
 * markers: () => program times drawn as vertical lines (stage 3's restarts).
 */
export function convergencePanel(el, getSeries, { idPrefix = 'conv', height = 180, markers = null } = {}) {
  const tabs = h('div', { class: 'tabs small', role: 'tablist', id: `${idPrefix}-tabs` });
  const grid = h('div', { class: 'conv-grid', id: `${idPrefix}-grid` });
  const empty = h('p', { class: 'muted', id: `${idPrefix}-empty` }, 'No estimates yet: the estimator waits for enough static positions and rotations.');
  el.append(tabs, empty, grid);
  let selected = localStorage.getItem(`imucal.${idPrefix}.group`) || groups()[0]?.key;
  let charts = new Map();  // coefficient -> chart
  let shownGroups = '';

  function groupsWithData(series) {
    const present = new Set();
    for (const name of series.keys()) present.add(groupOf(name)?.key || 'other');
    return [...groups().map((g) => g.key), 'other'].filter((k) => present.has(k));
  }

  function renderTabs(keys) {
    const sig = keys.join('|');
    if (sig === shownGroups) return;
    shownGroups = sig;
    clear(tabs);
    for (const k of keys) {
      const title = groups().find((g) => g.key === k)?.title || 'Other';
      tabs.append(h('button', { type: 'button', role: 'tab', dataset: { group: k }, 'aria-selected': String(k === selected),
        onclick: () => { selected = k; localStorage.setItem(`imucal.${idPrefix}.group`, k); rebuild(); } }, title));
    }
  }

  function rebuild() {
    for (const c of charts.values()) c.destroy();
    charts = new Map();
    clear(grid);
    for (const b of tabs.children) b.setAttribute('aria-selected', String(b.dataset.group === selected));
    update();
  }

  function update() {
    const series = getSeries();
    const keys = groupsWithData(series);
    empty.hidden = keys.length > 0;
    if (!keys.length) return;
    if (!keys.includes(selected)) {
      selected = keys[0];
    }
    renderTabs(keys);
    for (const b of tabs.children) b.setAttribute('aria-selected', String(b.dataset.group === selected));
    const names = [...series.keys()].filter((n) => (groupOf(n)?.key || 'other') === selected).sort();
    for (const name of names) {
      let chart = charts.get(name);
      if (!chart) {
        const box = h('div', { class: 'conv-chart', dataset: { coefficient: name } });
        grid.append(box);
        const suffix = name.slice(name.lastIndexOf('.') + 1);
        const color = AXIS_COLOR[suffix] || COLORS[0];
        chart = lineChart(box, {
          title: `${name}  [${unitOf(name)}]`, x: 'program s', y: unitOf(name), height,
          series: [{ label: 'estimate', color }, { label: '−σ', band: true }, { label: '+σ', band: true }],
          bands: [[3, 2, `${color}33`]],
          legend: false,
          markers: markers || undefined,
        });
        charts.set(name, chart);
      }
      const s = series.get(name);
      chart.setData(s.view(Infinity, 1500));
      const last = s.last(0), lo = s.last(1);
      chart.chart.root.title = `${name}: ${num(last)} ± ${num(last - lo, 2)} ${unitOf(name)}`;
    }
  }

  return {
    update: () => schedule(update),
    rebuild: () => schedule(rebuild),  // another set of coefficients (another estimator)
    destroy() {
      for (const c of charts.values()) c.destroy();
      charts.clear();
    },
  };
}
