// Events, alarms and suspensions as they happen on the live page, newest first (the last 200).
import { h, timeOfDay } from '../../format.mjs';

/** The card; add(e) puts a live event at its top. */
export function eventsCard() {
  const body = h('tbody', { id: 'events' });
  const empty = h('p', { class: 'muted', id: 'events-empty' }, 'Nothing has happened since this page connected.');
  const element = h('section', { class: 'card' }, h('h2', {}, 'Events, alarms and suspensions'),
    h('table', { class: 'list events' }, h('thead', {}, h('tr', {}, h('th', {}, 'time'), h('th', {}, 'campaign'), h('th', {}, 'event'), h('th', {}, 'reason'))), body),
    empty);
  function add(e) {
    empty.hidden = true;
    const what = e.kind === 'transition' ? `${e.from} → ${e.to}` : e.kind;
    const serious = ['suspended', 'alarm', 'error', 'interrupted'].includes(e.kind) || ['failed', 'suspended', 'aborted'].includes(e.to);
    body.prepend(h('tr', { class: serious ? 'event-serious' : '', dataset: { kind: e.kind } },
      h('td', {}, timeOfDay(e.t)), h('td', {}, e.campaign ?? ''), h('td', {}, what), h('td', {}, e.reason || '')));
    while (body.children.length > 200) body.lastChild.remove();
  }
  return { element, add };
}
