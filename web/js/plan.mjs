// The prediction of a campaign (POST /api/campaigns/plan, `imucal plan`, issue 16) as the builder
// shows it: each coefficient's predicted 1-sigma after the last stage that determines it, against a
// target. Pure: the daemon's answer and the targets come in, rows go out.
import { schema } from './schema.mjs';

/**
 * The seed's figures (method.md, stage 3): the default targets, by coefficient group (the name
 * without its axis), in imucald's order of the groups (GET /api/schema: plan::seed_targets()).
 * A new object each time: the builder edits its copy. Groups without a target are shown without
 * a verdict.
 */
export function seedTargets() {
  return { ...schema().seedTargets };
}

// Later stages refine earlier ones: a coefficient's prediction is the last of these that has it.
const STAGE_ORDER = ['direct', 'lever-arm', 'navigation'];

/** "gyro.bias_dph.x" -> "gyro.bias_dph"; "accel.lever_arm_mm.y.z" -> "accel.lever_arm_mm.y". */
export function groupOfName(name) {
  return name.slice(0, name.lastIndexOf('.'));
}

/**
 * @param {object} prediction  the daemon's imucal-plan/1 answer
 * @param {object} targets     group -> 1-sigma target (seedTargets() by default)
 * @returns {{name, group, stage, sigma, target: number|null, ratio: number|null, meets: boolean|null}[]}
 *   sorted by name; ratio = sigma / target.
 */
export function predictionRows(prediction, targets = seedTargets()) {
  const best = new Map();
  for (const stage of STAGE_ORDER) {
    const estimates = prediction?.stages?.[stage]?.estimates;
    if (!estimates) continue;
    for (const [name, pair] of Object.entries(estimates)) {
      const sigma = Array.isArray(pair) ? pair[1] : null;
      if (Number.isFinite(sigma) && sigma > 0) best.set(name, { stage, sigma });
    }
  }
  return [...best.entries()].sort(([a], [b]) => a.localeCompare(b)).map(([name, { stage, sigma }]) => {
    const group = groupOfName(name);
    const t = targets[group];
    const target = Number.isFinite(t) && t > 0 ? t : null;
    const ratio = target === null ? null : sigma / target;
    return { name, group, stage, sigma, target, ratio, meets: ratio === null ? null : ratio <= 1 };
  });
}

/** How many rows with a target meet it, of how many, and the worst ratio (null without targets). */
export function summary(rows) {
  const judged = rows.filter((r) => r.ratio !== null);
  const worst = judged.reduce((w, r) => (w === null || r.ratio > w.ratio ? r : w), null);
  return { met: judged.filter((r) => r.meets).length, judged: judged.length, worst };
}

/**
 * A stage's dominant source per coefficient from the prediction's budget (issue 34; stage 1,
 * `direct`, and stage 3, `navigation`, state one): name -> {source, share} (share: its part of
 * u², 0..1); empty without a budget.
 */
export function dominantSources(prediction, stage = 'direct') {
  const out = new Map();
  for (const [name, b] of Object.entries(prediction?.stages?.[stage]?.budget || {})) {
    const x = b.contributions?.[b.dominant];
    if (typeof x === 'number' && b.combined > 0) out.set(name, { source: b.dominant, share: (x * x) / (b.combined * b.combined) });
  }
  return out;
}

/**
 * What the bench must give for a stage's limits (the prediction's stages[stage].requirements;
 * stage 1's, `direct`, or stage 3's, `navigation`):
 * {sources: [{source, sigma, alone, withOthers}], wholeTable} with each bound
 * {maxSigma, maxFactor, limiting} (maxSigma null: no limit; maxFactor 0: none suffices, the
 * coefficient `limiting` exceeds its limit without the source); null without requirements.
 */
export function benchRequirements(prediction, stage = 'direct') {
  const req = prediction?.stages?.[stage]?.requirements;
  if (!req) return null;
  const bound = (b) => ({ maxSigma: b?.max_sigma ?? null, maxFactor: b?.max_factor ?? null, limiting: b?.limiting ?? null });
  return {
    sources: (req.sources || []).map((r) => ({ source: r.source, sigma: r.sigma, alone: bound(r.alone), withOthers: bound(r.with_others) })),
    wholeTable: req.whole_table ? bound(req.whole_table) : null,
  };
}
