// The estimators' card on the live page: each stage's status in this run, its counts, and what
// it still needs while it has not determined everything yet.
import { h, clear, duration, num } from '../../format.mjs';

/** The card; draw(run, estimators) shows the run's estimators (run null: nothing runs). */
export function estimatorStatus() {
  const box = h('div', { id: 'estimator-status' });
  const element = h('section', { class: 'card small', id: 'estimators-card' }, h('h2', {}, 'Estimators'), box);
  function draw(run, est) {
    const sig = JSON.stringify(Object.entries(est).map(([k, e]) => [k, e.status, e.statics, e.rotations, e.message, e.max_velocity_error_mps, e.max_position_error_m, e.filter_status, e.updates, Math.round(e.program_time_s || 0)]));
    if (box.dataset.sig === sig) return;
    box.dataset.sig = sig;
    clear(box);
    if (!Object.keys(est).length) box.append(h('p', { class: 'muted' }, run ? 'No estimator runs in this campaign.' : '—'));
    for (const [name, e] of Object.entries(est)) box.append(estimator(name, e));
  }
  return { element, draw };
}

function estimator(name, e) {
  // During a run, a stage that lacks data has not had its part of the program yet (or not
  // all of it): said neutrally, what it still needs folded away, not as a warning.
  const pending = e.status === 'undetermined' || e.status === 'waiting';
  const started = (e.statics ?? 0) > 0 || (e.updates ?? 0) > 0 || Object.keys(e.estimates || {}).length > 0;
  const label = pending ? (started ? 'not determined yet' : 'not reached yet') : e.status;
  return h('div', { class: 'estimator', dataset: { estimator: name, status: e.status } },
    h('strong', {}, name), ' ', h('span', { class: `badge est-${pending ? 'pending' : e.status}` }, label),
    e.statics !== undefined ? h('div', { class: 'muted' }, `${e.statics} statics, ${e.rotations ?? 0} rotations, at ${duration(e.program_time_s)}`) : null,
    e.max_velocity_error_mps !== undefined ? h('div', { class: 'muted' }, `max velocity error ${num(e.max_velocity_error_mps, 3)} m/s, position ${num(e.max_position_error_m, 3)} m`) : null,
    e.filter_status !== undefined ? h('div', { class: `muted filter-status${e.filter_status === 'running' ? '' : ' warn'}`, dataset: { filterStatus: e.filter_status.split(':')[0] } },
      `filter ${e.filter_status}; ${e.updates ?? 0} updates, ${e.rejected ?? 0} rejected, ${e.restarts ?? 0} restart(s), at ${duration(e.program_time_s)}`) : null,
    // The whole message: a stage that cannot determine something lists what, one per line.
    e.message && pending ? h('details', { class: 'estimator-needs' }, h('summary', {}, 'what it still needs'), h('div', { class: 'muted pre-line' }, e.message))
      : e.message ? h('div', { class: 'estimator-message' }, e.message) : null);
}
