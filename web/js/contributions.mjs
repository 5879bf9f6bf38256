// What each calibration stage contributed to the final model (issue 15): per coefficient, the value
// after the first stage, the change each later stage made, the final value and sigma, and for
// stage 3's states how much the filter shrank their uncertainty (sqrt(P0/Pk), from the stage's
// `uncertainty_reduction`). Pure: the models come in, rows go out (the results page draws them).
import { flatten, groupOf, orderOf, unitOf } from './coefficients.mjs';
import { schema } from './schema.mjs';

/**
 * The state of stage 3 a coefficient is, as [block, index] (the block as the stage's
 * uncertainty_reduction names it), or null: imucald's (GET /api/schema, from its filter's blocks).
 */
export function stateOf(name) {
  return schema().byKey.get(name)?.stage3_state || null;
}

/**
 * @param {{stage: string, model: object}[]} stages  each stage's model (the same frame), in pipeline order
 * @param {object|null} reduction  stage 3's uncertainty_reduction ({block: [sqrt(P0/Pk), ...]})
 * @returns {{name, group, unit, values: (number|null)[], changes: (number|null)[], final, sigma, reduction}[]}
 *   values[k]: the coefficient after stage k; changes[k]: what stage k added (changes[0] = values[0]).
 */
export function contributionRows(stages, reduction) {
  const flat = stages.map((s) => flatten(s.model));
  const last = stages.length ? stages[stages.length - 1].model : null;
  const sigma = flatten(last?.sigma);
  const names = new Set();
  for (const f of flat) for (const n of f.keys()) if (groupOf(n) && !n.includes('.noise.')) names.add(n);
  const rows = [];
  for (const name of names) {
    const values = flat.map((f) => (f.has(name) ? f.get(name) : null));
    const changes = values.map((v, k) => (k === 0 ? v : v === null || values[k - 1] === null ? null : v - values[k - 1]));
    // A coefficient no stage moved and none estimated (zero everywhere, no sigma) is left out.
    const s = sigma.has(name) ? sigma.get(name) : null;
    if (values.every((v) => v === 0 || v === null) && !(s > 0)) continue;
    const st = stateOf(name);
    const r = st && reduction && Array.isArray(reduction[st[0]]) ? reduction[st[0]][st[1]] : null;
    rows.push({ name, group: groupOf(name).title, unit: unitOf(name), values, changes,
      final: values[values.length - 1], sigma: s, reduction: Number.isFinite(r) ? r : null });
  }
  rows.sort((a, b) => orderOf(a.name) - orderOf(b.name) || (a.name < b.name ? -1 : 1));
  return rows;
}
