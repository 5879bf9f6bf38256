// What the estimators said about a campaign: each stage's facts (counts and quantities), its whole
// message and its notes.
import { h, num } from '../../format.mjs';
import { unitOf, labelOf } from '../../coefficients.mjs';

/** The notes of campaign results (d.results), or null when no stage said anything. */
export function stageNotes(results) {
  const notes = h('div', { class: 'stage-results', id: 'stage-results' });
  for (const [name, r] of Object.entries(results || {})) {
    const facts = Object.entries(r).filter(([k, v]) => k !== 'message' && (typeof v === 'number' || typeof v === 'string'));
    notes.append(h('div', { class: 'stage', dataset: { estimator: name } }, h('h3', {}, `${name}`),
      // Counts as integers ("22 statics"), quantities with their unit, names without it.
      h('dl', { class: 'meta compact' }, ...facts.flatMap(([k, v]) => [h('dt', {}, labelOf(k)),
        h('dd', {}, typeof v === 'number' ? (Number.isInteger(v) ? String(v) : `${num(v)} ${unitOf(k)}`.trim()) : v)])),
      // The whole message, one line each: a stage that cannot determine something lists what.
      typeof r.message === 'string' ? h('div', { class: 'estimator-message' }, r.message) : null,
      Array.isArray(r.notes) && r.notes.length ? h('ul', { class: 'notes' }, ...r.notes.map((n) => h('li', {}, n))) : null));
  }
  return notes.childElementCount ? notes : null;
}
