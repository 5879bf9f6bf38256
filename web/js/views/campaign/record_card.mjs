// The record of a campaign: its alarms (acknowledged here), transitions, events, segments and the
// campaign as stored.
import { h, clear, dateTime, stateBadge } from '../../format.mjs';
import { alarmTable } from '../../alarm_panel.mjs';

/** The card; show(d) draws campaign d's record; refresh() reads the campaign again (after an
 *  alarm was acknowledged); onError(text) says what failed. */
export function recordCard({ id, refresh, onError }) {
  const record = h('section', { class: 'card', id: 'record' });
  function show(d) {
    const cp = d.checkpoint?.segment;
    // Re-rendered every poll while the campaign runs: keep what the user opened open.
    const open = new Set([...record.querySelectorAll('details[open]')].map((x) => x.id));
    const alarms = d.alarms || [];
    clear(record).append(
      h('div', { class: 'record-head' }, h('h2', {}, 'Record'),
        h('a', { class: 'button', id: 'download-events', href: `/api/campaigns/${id}/events.csv`, download: `campaign-${id}-events.csv`,
          title: 'Transitions, events and alarms (raised, cleared, acknowledged by whom) as CSV' }, 'Download events (CSV)')),
      h('h3', {}, 'Alarms'),
      alarms.length
        ? alarmTable([...alarms].reverse(), { id: 'campaign-alarms', campaignColumn: false, onAcknowledged: () => refresh(),
          onError: (a, e) => { onError(`Alarm ${a.id}: ${e.message}`); refresh(); } })
        : h('p', { class: 'muted', id: 'no-alarms' }, 'No alarms.'),
      h('div', { class: 'two-col' },
        h('div', {}, h('h3', {}, 'Transitions'),
          h('table', { class: 'list compact', id: 'transitions' }, h('thead', {}, h('tr', {}, h('th', {}, 'time'), h('th', {}, 'from'), h('th', {}, 'to'), h('th', {}, 'reason'))),
            h('tbody', {}, ...(d.transitions || []).map((t) => h('tr', {}, h('td', {}, dateTime(t.t)), h('td', {}, t.from || '—'), h('td', {}, stateBadge(t.to)), h('td', {}, t.reason || '')))))),
        h('div', {}, h('h3', {}, 'Events'),
          (d.events || []).length ? h('table', { class: 'list compact', id: 'campaign-events' }, h('thead', {}, h('tr', {}, h('th', {}, 'time'), h('th', {}, 'kind'), h('th', {}, 'segment'), h('th', {}, 'reason'))),
            h('tbody', {}, ...d.events.map((e) => h('tr', { class: ['suspended', 'alarm', 'error', 'interrupted'].includes(e.kind) ? 'event-serious' : '' },
              h('td', {}, dateTime(e.t)), h('td', {}, e.kind), h('td', {}, segmentName(d, e.segment)), h('td', {}, e.reason || '')))))
            : h('p', { class: 'muted' }, 'No events.'))),
      h('details', { id: 'segments-details' }, h('summary', {}, `Segments (${(d.segments || []).length})`),
        h('table', { class: 'list compact' }, h('thead', {}, h('tr', {}, h('th', { class: 'num' }, '#'), h('th', {}, 'name'), h('th', {}, 'kind'), h('th', { class: 'num' }, 'from s'), h('th', { class: 'num' }, 'to s'), h('th', {}, 'redo'))),
          h('tbody', {}, ...(d.segments || []).map((s) => h('tr', { class: s.index === cp ? 'checkpoint' : '' },
            h('td', { class: 'num' }, s.index + 1), h('td', {}, s.name), h('td', {}, s.kind), h('td', { class: 'num' }, s.t0_s.toFixed(1)),
            h('td', { class: 'num' }, s.t1_s.toFixed(1)), h('td', {}, s.redoable ? 'yes' : 'no (chamber ramp)')))))),
      h('details', { id: 'spec-details' }, h('summary', {}, 'Campaign as stored (JSON)'), h('pre', { class: 'json-preview' }, JSON.stringify(d.spec, null, 1))));
    for (const x of record.querySelectorAll('details')) if (open.has(x.id)) x.open = true;
  }
  return { element: record, show };
}

// Events carry the segment's index (0-based, as in the daemon's own texts); its name says more.
function segmentName(d, index) {
  if (index === null || index === undefined) return '—';
  const s = (d.segments || [])[index];
  return s ? `${s.name} (${index})` : String(index);
}
