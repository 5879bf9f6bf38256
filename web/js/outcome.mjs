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

/**
 * Who paused a run, and how it goes on (issue 36, item 8), from its transitions (docs/api.md:
 * {t, from, to, reason}; imucald writes a command's reason as "pause by alice" or "pause by
 * alice: why"): {by, why, t, text}. `at` formats the transition's time for the text.
 */
export function pauseNote(transitions, at = (t) => t) {
  // The command's transition (running -> pausing) names who; the one into paused that follows,
  // when the table is at rest, may not.
  // Only this pause's: those since the run last went to running.
  const list = transitions || [];
  const since = list.map((x) => x.to).lastIndexOf('running');
  const pauses = list.slice(since + 1).reverse().filter((x) => x.to === 'pausing' || x.to === 'paused');
  const last = pauses.find((x) => /^pause by /.test(x.reason || '')) || pauses[0];
  const m = /^pause by ([^:]+?)(?::\s*(.*))?$/.exec(last?.reason || '');
  const by = m ? m[1] : null;
  const why = m ? m[2] || null : null;
  const who = by ? `Paused by ${by}${last?.t ? ` at ${at(last.t)}` : ''}${why ? ` (${why})` : ''}.` : 'Paused.';
  return { by, why, t: last?.t || null,
    text: `${who} The table holds still with its interlock open; nothing recorded is lost. To go on, an operator presses ` +
      'Resume (the table moves again and the interrupted segment is redone); Stop ends the run with what it has recorded.' };
}
