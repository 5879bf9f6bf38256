// A section of a campaign's results; its charts' destroy functions go into cleanups (the page's).
import { h, num, duration } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';

// The warm-up (IEEE 952): each channel's output from power-on less its settled value, with the
// fitted transient; the figures per channel with their sigma.
export function warmUpSection(w, cleanups) {
  const pm = ([v, s], digits) => `${num(v, digits)} ± ${num(s, 2)}`;
  const table = h('table', { class: 'list compact', id: 'warm-up-table' },
    h('thead', {}, h('tr', {}, h('th', {}, 'channel'), h('th', { class: 'num' }, 'transient at power-on'), h('th', { class: 'num' }, 'time constant'),
      h('th', { class: 'num' }, 'settled within the band after'), h('th', { class: 'num' }, 'band'))),
    h('tbody', {}, ...w.channels.map((c) => {
      const unit = c.unit === 'dph' ? '°/h' : 'µg';
      return h('tr', { dataset: { channel: `${c.sensor}.${c.axis}`, detected: String(c.detected) } },
        h('td', {}, `${c.sensor === 'gyro' ? 'gyro' : 'accelerometer'} ${c.axis}`),
        c.detected
          ? h('td', { class: 'num' }, `${pm(c.amplitude, 3)} ${unit}`)
          : h('td', { class: 'num muted' }, 'no transient above the noise'),
        h('td', { class: 'num' }, c.detected ? `${duration(c.time_constant_s[0])} ± ${duration(c.time_constant_s[1])}${c.resolved ? '' : ' (longer than the run)'}` : '—'),
        h('td', { class: 'num' }, c.detected ? `${duration(c.settle_time_s[0])} ± ${duration(c.settle_time_s[1])}` : '—'),
        h('td', { class: 'num' }, `± ${num(c.band, 2)} ${unit}`));
    })));
  const row = h('div', { class: 'plot-row' });
  const t_min = w.t_s.map((t) => t / 60);
  for (const [sensor, title, unit] of [['gyro', 'Gyro output from power-on, less its settled value', '°/h'], ['accel', 'Accelerometer output from power-on, less its settled value', 'µg']]) {
    const box = h('div', { class: 'plot', dataset: { kind: `warm-up-${sensor}` } });
    row.append(box);
    const channels = w.channels.map((c, i) => ({ c, i })).filter(({ c }) => c.sensor === sensor);
    const c = lineChart(box, { title, x: 'min since power-on', y: unit, height: 220, points: false,
      series: channels.flatMap(({ c: ch }, k) => [{ label: ch.axis, color: COLORS[k], width: 1 },
        { label: `${ch.axis} fit`, color: COLORS[k], width: 2, dash: [6, 4] }]) });
    c.setData([t_min, ...channels.flatMap(({ c: ch, i }) => [w.deviation[i],
      w.t_s.map((t) => (ch.detected ? ch.amplitude[0] * Math.exp(-t / ch.time_constant_s[0]) : 0))])]);
    cleanups.push(() => c.destroy());
  }
  return h('div', { id: 'warm-up' }, h('h3', {}, 'Warm-up: the bias transient from power-on (IEEE 952)'),
    h('p', { class: 'muted' }, `One static of ${duration(w.duration_s)} from power-on, averaged in bins and fitted with settled + amplitude · exp(−t / time constant) per channel. `,
      'Settled: the fitted transient stays inside the band from then on.'),
    table, row);
}
