// A table of campaigns (the campaigns view's "Running and queued", "Not started" and "History"):
// a row per campaign with its state, times and progress or result.
import { h, clear, duration, dateTime, outcomeBadge } from '../../format.mjs';

/** The table with its head; show(list) puts the campaigns in it, in the order given. */
export function campaignTable(id) {
  const body = h('tbody');
  const element = h('table', { class: 'list', id },
    h('thead', {}, h('tr', {},
      h('th', { class: 'num' }, '#'), h('th', {}, 'Name'), h('th', {}, 'Unit'), h('th', {}, 'Program'), h('th', {}, 'State'),
      h('th', {}, 'Created'), h('th', {}, 'Started'), h('th', { class: 'num' }, 'Program length'),
      h('th', { class: 'num' }, 'Wall time'), h('th', {}, 'Progress / result'))),
    body);
  return { element, show: (list) => clear(body).append(...list.map(campaignRow)) };
}

function campaignRow(c) {
  const wall = c.started ? ((c.ended ? Date.parse(c.ended) : Date.now()) - Date.parse(c.started)) / 1000 : null;
  return h('tr', { dataset: { id: c.id, state: c.state }, class: `state-row-${c.state}` },
    h('td', { class: 'num' }, c.id),
    h('td', {}, h('a', { href: `#/campaigns/${c.id}` }, c.name)),
    // The unit's page: its calibrations and their trends.
    h('td', {}, c.imu ? h('a', { class: 'unit-link', href: `#/imus/${encodeURIComponent(c.imu.serial)}` }, c.imu.serial) : ''),
    h('td', {}, c.program),
    h('td', {}, outcomeBadge(c), c.queue_position != null ? h('span', { class: 'muted' }, ` #${c.queue_position + 1} in queue`) : ''),
    h('td', {}, dateTime(c.created)),
    h('td', {}, dateTime(c.started)),
    h('td', { class: 'num' }, duration(c.duration_s)),
    h('td', { class: 'num' }, duration(wall)),
    h('td', {}, campaignResult(c)));
}

function campaignResult(c) {
  // A run stopped early ends done all the same: it is partial, and says so.
  if (c.state === 'done' && !c.complete)
    return h('span', { class: c.accepted ? 'result-ok' : 'muted', title: c.accepted ? `accepted: ${c.accepted.reason}` : '' },
      `partial: stopped at ${Math.round(100 * (c.progress || 0))} %${c.has_model ? ', model kept' : ''}${c.accepted ? ', accepted' : ''}`);
  if (c.state === 'done')
    return c.has_model ? h('a', { class: 'result-ok', href: `#/campaigns/${c.id}` }, 'model ready — see results')
      : h('span', { class: 'muted' }, 'finished without a model');
  // Aborted and failed runs keep what the data so far gave: partial, never a calibration
  // unless accepted.
  const kept = `${c.has_model ? ', model kept (partial)' : ''}${c.accepted ? ', accepted' : ''}`;
  if (c.state === 'failed') return h('span', { class: 'result-bad', title: c.error || '' }, `${c.error || 'failed'}${kept}`);
  if (c.state === 'aborted') return h('span', { class: 'muted' }, `aborted at ${Math.round(100 * (c.progress || 0))} %${kept}`);
  if (c.state === 'created') return h('span', { class: 'muted' }, 'not started');
  if (c.state === 'queued') return h('span', { class: 'muted' }, 'waits for the bench');
  const pct = Math.round(100 * (c.progress || 0));
  return h('div', { class: 'progress', title: `${pct} % of the program` },
    h('div', { class: 'bar', style: `width:${pct}%` }), h('span', {}, `${pct} %`));
}
