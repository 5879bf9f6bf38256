// One unit's page (issue 17): its calibrations from the registry (GET /api/imus/{serial}), partial
// runs marked as such, and a chosen coefficient over the calibrations as a trend with its sigma.
import { get } from '../api.mjs';
import { h, clear, dateTime, stateBadge } from '../format.mjs';
import { lineChart, COLORS } from '../plots.mjs';
import { flatten, orderOf, unitOf } from '../coefficients.mjs';

export function mount(root, ctx) {
  const serial = ctx.params.serial;
  const url = `/api/imus/${encodeURIComponent(serial)}`;
  const status = h('div', { class: 'form-error', role: 'alert', id: 'unit-error' });
  const info = h('p', { class: 'muted', id: 'unit-info' });
  const body = h('tbody', { id: 'unit-calibrations' });
  const select = h('select', { id: 'unit-coefficient' });
  const plotBox = h('div', { class: 'plot', id: 'unit-trend' });
  let chart = null;
  let calibrations = [];

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, `Unit ${serial}`),
      h('div', { class: 'actions' },
        h('a', { class: 'button', id: 'unit-csv', href: `${url}/history.csv`, download: `imu-${serial}-history.csv` }, 'History (CSV)'))),
    status, info,
    h('section', { class: 'card' }, h('h2', {}, 'Calibrations'),
      h('table', { class: 'list', id: 'unit-table' },
        h('thead', {}, h('tr', {}, h('th', { class: 'num' }, '#'), h('th', {}, 'Name'), h('th', {}, 'Program'),
          h('th', {}, 'Ended'), h('th', {}, 'State'), h('th', {}, 'Counts as a calibration'))),
        body)),
    h('section', { class: 'card' }, h('h2', {}, 'Trend'),
      h('div', { class: 'actions' }, h('label', { for: 'unit-coefficient' }, 'Coefficient'), select),
      h('p', { class: 'hint' }, 'Each calibration with a model, oldest first; the band is ±1 sigma.'), plotBox));

  select.addEventListener('change', () => plot(select.value));

  function counts(c) {
    if (c.counts && c.complete) return 'yes';
    if (c.counts) return `yes, partial run accepted: ${c.accepted?.reason || ''}`;
    if (!c.model) return 'no: no model';
    return `no: partial (${Math.round(100 * (c.progress || 0))} % of the program), not accepted`;
  }

  function plot(name) {
    const points = calibrations.filter((c) => c.model);
    const values = points.map((c) => flatten(c.model).get(name) ?? null);
    const sigmas = points.map((c) => (c.model.sigma ? flatten(c.model.sigma).get(name) ?? null : null));
    const hi = values.map((v, i) => (v == null || sigmas[i] == null ? null : v + sigmas[i]));
    const lo = values.map((v, i) => (v == null || sigmas[i] == null ? null : v - sigmas[i]));
    if (chart) chart.destroy();
    clear(plotBox);
    chart = lineChart(plotBox, { title: `${name} [${unitOf(name)}]`, x: 'calibration', y: unitOf(name), height: 220, points: true,
      series: [{ label: 'value', color: COLORS[0] }, { label: '+1σ', band: true }, { label: '−1σ', band: true }],
      bands: [[2, 3, 'rgba(21,101,192,0.15)']] });
    chart.setData([points.map((_, i) => i + 1), values, hi, lo]);
  }

  (async () => {
    try {
      const u = await get(url);
      calibrations = u.calibrations || [];
      info.textContent = `${u.part_number ? `Part number ${u.part_number}. ` : ''}${u.calibrations_counted} calibration${u.calibrations_counted === 1 ? '' : 's'} counted of ${calibrations.length} ended campaign${calibrations.length === 1 ? '' : 's'}.`;
      clear(body).append(...calibrations.map((c) => h('tr', { dataset: { id: c.campaign_id, complete: String(c.complete) } },
        h('td', { class: 'num' }, h('a', { href: `#/campaigns/${c.campaign_id}` }, c.campaign_id)),
        h('td', {}, c.name), h('td', {}, c.program), h('td', {}, dateTime(c.date)),
        h('td', {}, stateBadge(c.state), c.complete ? '' : h('span', { class: 'result-bad' }, ' partial')),
        h('td', {}, counts(c)))));
      const names = new Set();
      for (const c of calibrations) if (c.model) for (const n of flatten(c.model).keys()) names.add(n);
      const sorted = [...names].sort((a, b) => orderOf(a) - orderOf(b) || a.localeCompare(b));
      clear(select).append(...sorted.map((n) => h('option', { value: n }, `${n} [${unitOf(n)}]`)));
      if (sorted.length) plot(sorted[0]);
    } catch (e) {
      status.textContent = `Cannot load unit ${serial}: ${e.message}`;
    }
  })();

  return () => { if (chart) chart.destroy(); };
}
