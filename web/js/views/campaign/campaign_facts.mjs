// The facts of one campaign: its unit, program, times, frames, checkpoint, estimators, queue
// position and run database; who paused it and how it goes on; and, while it is the active run,
// a strip of where it is with a link to the live view.
import { h, clear, duration, dateTime, timeOfDay } from '../../format.mjs';
import { pauseNote } from '../../outcome.mjs';

/** The card; show(d) draws campaign d's facts, showLive(run) the strip (run null: it is not the
 *  active run). */
export function campaignFacts() {
  const meta = h('dl', { class: 'meta', id: 'campaign-meta' });
  const liveStrip = h('div', { class: 'live-strip', id: 'campaign-live', hidden: true });
  const pausedBanner = h('div', { class: 'suspended-banner paused-banner', id: 'paused-banner', role: 'status', hidden: true });
  const element = h('section', { class: 'card' }, meta, pausedBanner, liveStrip);

  function show(d) {
    const wall = d.started ? ((d.ended ? Date.parse(d.ended) : Date.now()) - Date.parse(d.started)) / 1000 : null;
    // The unit under test first (issue 36, item 8): its serial links to its history.
    const imu = d.imu || d.spec?.imu || {};
    const rows = [
      ['unit', imu.serial ? h('a', { href: `#/imus/${encodeURIComponent(imu.serial)}`, id: 'campaign-unit' }, imu.serial) : 'not named'],
      ['part number', imu.part_number || '—'],
      ['program', d.program], ['created', dateTime(d.created)], ['started', dateTime(d.started)], ['ended', dateTime(d.ended)],
      ['program length', duration(d.duration_s)], ['program time', `${duration(d.program_time_s)} (${Math.round(100 * (d.progress || 0))} %)`],
      ['wall time', duration(wall)], ['frames', `${d.frames ?? '—'} recorded, ${d.lost_frames ?? 0} lost, ${d.bad_frames ?? 0} bad`],
      ['checkpoint', d.checkpoint ? `segment ${d.checkpoint.segment + 1} at ${duration(d.checkpoint.t_s)}` : '—'],
      ['estimators', (d.spec?.estimators || []).join(', ') || '—'],
      ['queue', d.queue_position != null ? `position ${d.queue_position + 1}` : '—'],
      ['run database', d.run_db || '—'],
    ];
    if (d.error) rows.push(['error', d.error]);
    clear(meta).append(...rows.flatMap(([k, v]) => [h('dt', {}, k), h('dd', { class: k === 'error' ? 'result-bad' : '' }, v ?? '—')]));
    const paused = d.state === 'paused' || d.state === 'pausing';
    pausedBanner.hidden = !paused;
    if (paused) pausedBanner.textContent = pauseNote(d.transitions, timeOfDay).text;
  }

  function showLive(run) {
    liveStrip.hidden = !run;
    if (!run) return;
    const seg = run.segment || {};
    const text = `Live: ${run.state}, step ${seg.index + 1}/${seg.count} ${seg.name}, program ${duration(run.program_time_s)} of ${duration(run.duration_s)}, ${duration(run.time_left_s)} left`;
    if (liveStrip.firstChild?.textContent !== text) {
      clear(liveStrip).append(h('span', {}, text), ' ', h('a', { href: '#/live' }, 'open the live view'));
    }
  }
  return { element, show, showLive };
}
