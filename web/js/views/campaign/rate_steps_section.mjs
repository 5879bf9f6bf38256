// A section of a campaign's results; its charts' destroy functions go into cleanups (the page's).
import { h, num } from '../../format.mjs';
import { lineChart, COLORS } from '../../plots.mjs';

// The rate-steps stage's figures (docs/api.md, results.rate-steps.rate_steps): a table of the
// IEEE 952 figures per gyro and, per gyro, each step's scale error at its rate with the fitted
// model through them.
export function rateStepsSection(rs, cleanups) {
  const pm = (pair, digits = 3) => (Array.isArray(pair) ? `${num(pair[0], 5)} ± ${num(pair[1], 2)}` : '—');
  const terms = (a) => (a.scale_nonlinear_ppm.length
    ? a.scale_nonlinear_ppm.map((c, k) => `c${k + 1} ${pm(c)}`).join(', ') : 'none (linear)');
  const tableEl = h('table', { class: 'list compact', id: 'rate-steps-table' },
    h('thead', {}, h('tr', {}, h('th', {}, 'gyro'), h('th', { class: 'num' }, 'scale + ppm'), h('th', { class: 'num' }, 'scale − ppm'),
      h('th', { class: 'num' }, 'asymmetry ppm'), h('th', { class: 'num' }, 'nonlinearity ppm of full scale'),
      h('th', {}, 'nonlinear terms ppm (q = |ω| / 100 °/s)'), h('th', { class: 'num' }, 'steps'))),
    h('tbody', {}, ...rs.axes.map((a) => h('tr', { dataset: { axis: a.axis } }, h('td', {}, a.axis),
      h('td', { class: 'num' }, pm(a.scale_pos_ppm)), h('td', { class: 'num' }, pm(a.scale_neg_ppm)),
      h('td', { class: 'num' }, pm(a.asymmetry_ppm)),
      h('td', { class: 'num' }, `${pm(a.nonlinearity_ppm_fs)} (at ${num(a.nonlinearity_at_dps, 3)} °/s of ${num(a.full_scale_dps, 3)})`),
      h('td', {}, terms(a)), h('td', { class: 'num' }, String(a.steps.length))))));
  const row = h('div', { class: 'plot-row wrap' });
  for (const a of rs.axes) {
    const box = h('div', { class: 'plot third', dataset: { axis: a.axis } });
    row.append(box);
    const c = lineChart(box, { title: `Gyro ${a.axis}: scale error against rate`, x: 'rate °/s', y: 'ppm', height: 220, points: true,
      series: [{ label: 'step', color: COLORS[1], width: 0 }, { label: 'step − σ', band: true }, { label: 'step + σ', band: true },
        { label: `model (degree ${a.degree})`, color: COLORS[0], width: 1.5 }],
      bands: [[3, 2, 'rgba(198, 40, 40, 0.15)']] });
    const steps = a.steps;
    c.setData([steps.map((st) => st.rate_dps), steps.map((st) => st.scale_ppm[0]),
      steps.map((st) => st.scale_ppm[0] - st.scale_ppm[1]), steps.map((st) => st.scale_ppm[0] + st.scale_ppm[1]),
      steps.map((st) => st.model_ppm[0])]);
    cleanups.push(() => c.destroy());
  }
  return h('div', { id: 'rate-steps' }, h('h3', {}, 'Scale factor against rate (rate-steps test, IEEE 952)'),
    h('p', { class: 'muted' }, 'Each step: the scale error at its cruise rate, ± σ (shaded). The model: the scale factors at zero rate ',
      'and the nonlinear terms, with the degree chosen by how well it predicts each rate left out. The nonlinearity is the largest ',
      'deviation of the output from its least-squares line over both signs (so an asymmetry shows in it too).'),
    tableEl, row);
}
