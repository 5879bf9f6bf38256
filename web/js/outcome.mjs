// What an ended run amounts to, one word for every list (issue 35): the state alone says `done`
// for a run the operator stopped half-way, and a failed run accepted as a calibration is still
// `failed`. Pure (no DOM), so node's unit tests check it.
//
//   done     the program ran to its end
//   stopped  ended early by a stop, not accepted as a calibration
//   partial  ended early (stopped, failed or aborted) and accepted by an operator as a calibration
//   failed   ended on an error, not accepted
//   aborted  aborted, not accepted
// A run not ended yet is its state (running, paused, ...).
export function runOutcome(c) {
  const state = c?.state || 'unknown';
  if (!['done', 'failed', 'aborted'].includes(state)) return { outcome: state, title: state };
  // Runs stored before `complete` existed, and the registry's rows, say complete: true when done.
  const complete = c.complete !== false && state === 'done';
  const accepted = Boolean(c.accepted);
  if (complete) return { outcome: 'done', title: 'the program ran to its end' };
  if (accepted) {
    return { outcome: 'partial', title: `ended ${state === 'done' ? 'early (stopped)' : state}; accepted as a calibration: ${c.accepted.reason || ''}` };
  }
  if (state === 'done') return { outcome: 'stopped', title: 'stopped before the end of its program; not a calibration unless accepted' };
  return { outcome: state, title: state === 'failed' ? (c.error || 'ended on an error') : 'aborted by an operator' };
}
