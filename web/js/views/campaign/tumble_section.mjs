// A section of a campaign's results; its charts' destroy functions go into cleanups (the page's).
import { h, num } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';

// The tumble's residuals (docs/api.md, results.tumble.tumble): what every static left after the
// fit, per accelerometer and per gyro, in the order of the positions (two whole turns).
export function tumbleSection(t, cleanups) {
  const row = h('div', { class: 'plot-row' });
  const index = t.positions.map((_, i) => i + 1);
  for (const [key, title, unit, rms] of [['accel_residual_ug', 'Accelerometer residuals', 'µg', t.accel_residual_rms_ug],
    ['gyro_residual_dph', 'Gyro residuals', '°/h', t.gyro_residual_rms_dph]]) {
    const box = h('div', { class: 'plot', dataset: { kind: key } });
    row.append(box);
    const c = lineChart(box, { title: `${title} (rms ${rms.map((v) => num(v, 2)).join(', ')} ${unit})`, x: 'position', y: unit,
      height: 200, points: true, series: ['x', 'y', 'z'].map((a, i) => ({ label: a, color: COLORS[i], width: 1 })) });
    c.setData([index, ...[0, 1, 2].map((j) => t.positions.map((p) => p[key][j]))]);
    cleanups.push(() => c.destroy());
  }
  return h('div', { id: 'tumble' }, h('h3', {}, 'Tumble: what every position left after the fit (IEEE 1293)'),
    h('p', { class: 'muted' }, `${t.positions.length} statics: bias, scale, K2, K3 and angles per accelerometer, bias and `,
      'g-sensitivity per gyro (in the coefficient table). Residuals that follow the position (a pattern, not noise) mean a term the model lacks.'),
    row);
}
