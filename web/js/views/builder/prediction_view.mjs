// The builder's prediction laid out (POST /api/campaigns/plan, plan.mjs): its status line, every
// coefficient's 1-sigma against its target with the source that limits it, the bench each
// stage's limits need, and what the program determines weakly or not at all.
import { h, clear, duration, num } from '../../format.mjs';
import { predictionRows, summary, dominantSources, benchRequirements } from '../../plan.mjs';
import { sourceName } from '../../budget.mjs';

/** Shows prediction p judged against targets in els ({planStatus, planTable, planBody,
 *  planBench, planWeak}); ownRate: the campaign's frame rate. */
export function showPrediction(els, p, targets, ownRate) {
  const { planStatus, planTable, planBody, planBench, planWeak } = els;
  const rows = predictionRows(p, targets);
  const s = summary(rows);
  planStatus.dataset.state = s.judged && s.met === s.judged ? 'valid' : 'invalid';
  delete planTable.dataset.stale;
  planStatus.textContent = `${duration(p.duration_s)} of program at ${rateText(ownRate, p.rate_hz)}: ${s.met} of ${s.judged} targets met` +
    (s.worst && !s.worst.meets ? `; worst ${s.worst.name} at ${num(s.worst.ratio, 2)}× its target.` : '.');
  clear(planBody);
  const dominant = { direct: dominantSources(p, 'direct'), navigation: dominantSources(p, 'navigation') };
  for (const row of rows) {
    // The dominant source of the stage that predicts the row (stage 1's or stage 3's budget).
    const d = dominant[row.stage]?.get(row.name) ?? null;
    // Four columns fit the side panel: the stage under the name, the name breakable after each dot.
    planBody.append(h('tr', { class: row.meets === false ? 'misses' : row.meets ? 'meets' : '', dataset: { name: row.name, stage: row.stage } },
      h('td', {}, row.name.split('.').flatMap((p, i) => (i ? [h('wbr'), `.${p}`] : [p])), h('span', { class: 'plan-stage' }, row.stage)),
      h('td', { class: 'num' }, num(row.sigma, 3)),
      h('td', { class: 'num' }, row.target === null ? '' : num(row.target, 3)),
      h('td', { class: 'dominant' }, d ? `${sourceName(d.source)} (${Math.round(100 * d.share)} %)` : '')));
  }
  clear(planBench);
  showBench(planBench, benchRequirements(p, 'direct'), 'stage 1');
  showBench(planBench, benchRequirements(p, 'navigation'), 'stage 3');
  clear(planWeak);
  for (const w of p.weak || [])
    planWeak.append(h('li', { class: 'problem' }, `${w.coefficient} (${w.stage}): ${w.why}; needs ${w.fix}`));
  // The nonlinear terms the program does not determine: taken from the model, said as such.
  for (const w of p.from_model || [])
    planWeak.append(h('li', { class: 'from-model', dataset: { coefficient: w.coefficient } }, `${w.coefficient}: ${w.why}; to determine it, ${w.fix}`));
  // The tumble's terms determined less well than the unit needs (issue 34).
  for (const w of p.short_of_needs || [])
    planWeak.append(h('li', { class: 'problem short-of-needs', dataset: { coefficient: w.coefficient } }, `${w.coefficient} (${w.stage}): ${w.why}; needs ${w.fix}`));
}

// The campaign's own frame rate, and the one the prediction simulated when that differs.
// imucald simulates at 20 Hz unless told (docs/api.md): a 6 h program's prediction took 45 s at
// 20 Hz on the 2-core test machine and grows with the rate, while the σ it predicts do not
// (the sensors' white noise is a density: its effect on a static's mean depends on the time,
// not the frames; \`imucal plan\` on direct-short gives the same σ within 0.5 % at 20 and 100 Hz).
function rateText(own, simulatedHz) {
  const hz = (v) => `${Number(v.toPrecision(6))} Hz`;  // 50 Hz as typed, not "50.0 Hz"
  if (!(own > 0) || own === simulatedHz) return hz(simulatedHz);
  return `the campaign's ${hz(own)} (simulated at ${hz(simulatedHz)}: white noise's σ does not depend on the frame rate)`;
}

// The bench for a stage's limits: per source its 1-sigma and the largest that still meets them.
function showBench(planBench, req, stageName) {
  if (!req) return;
  const text = (b) => (b.maxSigma === null && b.maxFactor === null ? 'no limit'
    : b.maxFactor === 0 ? `none suffices (${b.limiting})` : `≤ ${num(b.maxSigma ?? b.maxFactor, 3)} (${b.limiting})`);
  const first = stageName === 'stage 1';
  planBench.append(h('h3', {}, `Bench for ${stageName}'s limits`),
    req.sources.length === 0
      ? h('p', { class: 'hint' }, 'No table certificate in imucald\'s configuration (table): the table\'s errors are not in the budget.')
      : h('table', { class: 'plan-table', id: first ? 'plan-bench-table' : 'plan-bench-table-stage3' },
        h('thead', {}, h('tr', {}, h('th', {}, 'Source'), h('th', { class: 'num' }, '1σ'), h('th', {}, 'Alone'), h('th', {}, 'With the others'))),
        h('tbody', {}, ...req.sources.map((r) => h('tr', { dataset: { source: r.source } },
          h('td', {}, sourceName(r.source)), h('td', { class: 'num' }, num(r.sigma, 3)), h('td', {}, text(r.alone)), h('td', {}, text(r.withOthers)))))),
    req.wholeTable ? h('p', { class: 'hint', id: first ? 'plan-whole-table' : 'plan-whole-table-stage3' },
      `The whole table certificate scaled together (no g error): ${req.wholeTable.maxFactor === null ? 'no limit' : `at most ${num(req.wholeTable.maxFactor, 3)}× (${req.wholeTable.limiting})`}.`) : null,
  );
}
