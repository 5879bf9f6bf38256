// The results' coefficient table: the model's coefficients with their sigmas, gyros on the left,
// accelerometers and the rest on the right, and in a simulated run the truth, the error and the
// error in sigmas, those beyond 3 σ marked.
import { h, num } from '../../format.mjs';
import { coefficientRows, groupOf } from '../../coefficients.mjs';

export function coefficientTable(model, truth, simulated) {
  const all = coefficientRows(model, truth);
  const rows = all.filter((r) => r.estimated || groupOf(r.name));
  const skipped = [...new Set(all.filter((r) => !rows.includes(r)).map((r) => r.name.replace(/\.[xyz]$/, '')))];
  const withTruth = truth !== null;
  // Gyros on the left, accelerometers and the rest on the right: the whole model on one screen.
  const left = rows.filter((r) => r.name.startsWith('gyro.') && !r.name.includes('.noise.') && r.group !== 'Other');
  const right = rows.filter((r) => !left.includes(r));
  const bads = rows.filter((r) => r.ratio !== null && Math.abs(r.ratio) > 3).length;
  const frame = model.frame || 'instrument';
  const zeros = rows.filter((r) => r.byDefinition).map((r) => r.name);
  return h('div', { class: 'coefficients' },
    h('h3', {}, `Coefficients (${frame} frame)`),
    withTruth ? h('p', { class: bads ? 'result-bad' : 'result-ok', id: 'truth-verdict', dataset: { frame: truth.frame, truthFrame: truth.truth_frame } },
      bads ? `${bads} coefficient(s) are more than 3 σ from the simulation's truth (marked).` : 'Every coefficient is within 3 σ of the simulation\'s truth.',
      truth.converted ? ` The truth, written in the ${truth.truth_frame} frame, is compared in the ${truth.frame} frame.` : '',
      zeros.length ? ` ${zeros.join(', ')}: 0 by definition of the ${frame} frame (not judged).` : '')
      : (simulated ? h('p', { class: 'muted' }, 'The truth of this simulated run could not be read; the error is not shown.') : null),
    h('div', { class: 'coefficient-columns', id: 'coefficient-table' }, table(left, withTruth, frame), table(right, withTruth, frame)),
    skipped.length ? h('p', { class: 'muted' }, `Not estimated by this campaign (zero with zero σ in the model): ${skipped.join(', ')}.`) : null);
}

function table(rows, withTruth, frame) {
  const body = h('tbody');
  let group = null;
  for (const r of rows) {
    if (r.group !== group) {
      group = r.group;
      body.append(h('tr', { class: 'group-row' }, h('th', { colspan: withTruth ? 7 : 4 }, group)));
    }
    const bad = r.ratio !== null && Math.abs(r.ratio) > 3;
    const data = { coefficient: r.name };
    if (r.ratio !== null) data.ratio = String(r.ratio);
    if (r.byDefinition) {
      data.byDefinition = 'true';
      body.append(h('tr', { dataset: data, class: 'by-definition' },
        h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
        h('td', { class: 'unit' }, r.unit),
        h('td', { class: 'num estimate', colspan: withTruth ? 5 : 2 }, `0 by definition of the ${frame} frame`)));
      continue;
    }
    body.append(h('tr', { dataset: data, class: bad ? 'out-3sigma' : '' },
      h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
      h('td', { class: 'unit' }, r.unit),
      h('td', { class: 'num estimate' }, num(r.estimate, 5)),
      h('td', { class: 'num sigma' }, r.sigma === null ? '—' : num(r.sigma, 2)),
      withTruth ? h('td', { class: 'num truth' }, r.truth === null ? '—' : num(r.truth, 5)) : null,
      withTruth ? h('td', { class: 'num error' }, r.error === null ? '—' : num(r.error, 3)) : null,
      withTruth ? h('td', { class: 'num ratio', title: 'error in sigmas; beyond ±3 is marked' }, r.ratio === null ? '—' : r.ratio.toFixed(2)) : null));
  }
  return h('table', { class: 'list compact coefficient-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'coefficient'), h('th', {}, 'unit'), h('th', { class: 'num' }, 'estimate'), h('th', { class: 'num' }, 'σ'),
        withTruth ? [h('th', { class: 'num' }, 'truth'), h('th', { class: 'num' }, 'error'), h('th', { class: 'num' }, 'error / σ')] : null)),
      body);
}
