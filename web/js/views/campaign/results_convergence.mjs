// The convergence over a finished run (GET .../progress): one estimator's estimate ± σ over
// program time, stage 3's when it ran (the final refinement), else stage 1's, else the first.
import { h } from '../../format.mjs';
import { convergencePanel } from '../../convergence.mjs';
import { Series } from '../../series.mjs';

/** Appends the heading and the panel to results when the progress has estimates; the panel's
 *  destroy function goes into cleanups (the page's). */
export function resultsConvergence(results, progress, cleanups) {
  // Only stages whose progress carries estimates (the warm-up and repeatability report counts).
  const converging = Object.keys(progress || {}).filter((n) => (progress[n] || []).some((p) => Object.keys(p.estimates || {}).length));
  if (!converging.length) return;
  const name = converging.includes('stage3') ? 'stage3' : converging.includes('direct') ? 'direct' : converging[0];
  const restarts = (progress[name] || []).reduce((r, p) => (Array.isArray(p.restart_times_s) ? p.restart_times_s : r), []);
  const map = new Map();
  for (const p of progress[name] || []) {
    for (const [coef, pair] of Object.entries(p.estimates || {})) {
      if (!Array.isArray(pair)) continue;
      if (!map.has(coef)) map.set(coef, new Series(3, { recentCapacity: 4000, historyCapacity: 2000 }));
      const [v, s] = pair;
      map.get(coef).push(p.program_time_s, [v, v - s, v + s]);
    }
  }
  if (!map.size) return;
  const box = h('div', { id: 'results-convergence' });
  results.append(h('h3', {}, `Convergence of the ${name} estimator (estimate ± σ over program time)`), box);
  const panel = convergencePanel(box, () => map, { idPrefix: 'res-conv', markers: () => restarts });
  panel.update();
  cleanups.push(() => panel.destroy());
}
