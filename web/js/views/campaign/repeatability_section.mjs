// A section of a campaign's results; its charts' destroy functions go into cleanups (the page's).
import { h, num } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';

// Turn-on to turn-on repeatability (IEEE 952): per channel the 1-sigma bias change from one
// power-on to the next with its intervals, and each power-on's bias against the mean.
export function repeatabilitySection(r, cleanups) {
  const unitOfChannel = (c) => (c.unit === 'dph' ? '°/h' : 'µg');
  const range = ([lo, hi]) => `${num(lo, 3)} … ${num(hi, 3)}`;
  const table = h('table', { class: 'list compact', id: 'repeatability-table' },
    h('thead', {}, h('tr', {}, h('th', {}, 'channel'), h('th', { class: 'num' }, 'repeatability (1σ)'), h('th', { class: 'num' }, '68 % interval'),
      h('th', { class: 'num' }, '99.73 % interval'), h('th', { class: 'num' }, 'spread of the biases'), h('th', { class: 'num' }, 'noise in each'))),
    h('tbody', {}, ...r.channels.map((c) => h('tr', { dataset: { channel: `${c.sensor}.${c.axis}` } },
      h('td', {}, `${c.sensor === 'gyro' ? 'gyro' : 'accelerometer'} ${c.axis}`),
      h('td', { class: 'num' }, `${num(c.repeatability[0], 3)} ± ${num(c.repeatability[1], 2)} ${unitOfChannel(c)}`),
      h('td', { class: 'num' }, range(c.interval_68)), h('td', { class: 'num' }, range(c.interval_997)),
      h('td', { class: 'num' }, num(c.spread, 3)), h('td', { class: 'num' }, num(c.noise, 2))))));
  const row = h('div', { class: 'plot-row' });
  const index = r.turn_ons.map((t) => t.index);
  for (const [offset, title, unit] of [[0, 'Gyro bias at each power-on, less their mean', '°/h'], [3, 'Accelerometer bias at each power-on, less their mean', 'µg']]) {
    const box = h('div', { class: 'plot', dataset: { kind: `repeatability-${offset ? 'accel' : 'gyro'}` } });
    row.append(box);
    const c = lineChart(box, { title, x: 'power-on', y: unit, height: 200, points: true,
      series: ['x', 'y', 'z'].map((a, i) => ({ label: a, color: COLORS[i], width: 1 })) });
    c.setData([index, ...[0, 1, 2].map((j) => r.turn_ons.map((t) => t.offset[offset + j]))]);
    cleanups.push(() => c.destroy());
  }
  return h('div', { id: 'repeatability' }, h('h3', {}, 'Turn-on to turn-on bias repeatability (IEEE 952)'),
    h('p', { class: 'muted' }, `${r.turn_ons.length} power-ons at one orientation, each a static after its settle time. `,
      'The repeatability is the spread of their biases less the noise within each static; a standard deviation from a few power-ons is uncertain, hence the intervals (chi-square).'),
    table, row);
}
