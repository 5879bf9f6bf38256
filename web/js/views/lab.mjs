// The lab overview (issue 38, docs/api.md "GET /api/lab"): every stand of the lab's registry,
// online or not, what it runs with its progress, its alarms, and a link to its own page. Read
// again every few seconds: the stands report on their own heartbeat, not on this page's events.
import { get } from '../api.mjs';
import { h, clear, dateTime, stateBadge } from '../format.mjs';

// Only a web address is followed: the rows come from every stand of the lab.
function standLink(s) {
  const safe = /^https?:\/\//i.test(s.url || '');
  const label = s.this ? `${s.name} (this stand)` : s.name;
  return safe ? h('a', { href: s.url, class: 'stand-link', rel: 'noopener' }, label) : h('span', {}, label);
}

function runCell(s) {
  const r = s.run;
  if (!r) return h('span', { class: 'muted' }, s.queue ? `idle, ${s.queue} queued` : 'idle');
  const pct = Math.round(100 * (r.progress || 0));
  const unit = r.imu && r.imu.serial ? `, unit ${r.imu.serial}` : '';
  return h('div', { class: 'stand-run' },
    h('div', {}, stateBadge(r.state), ` #${r.id} ${r.name} (${r.program}${unit})`),
    h('div', { class: 'progress wide', title: `${pct} % of the program` },
      h('div', { class: 'bar', style: `width:${pct}%` }), h('span', {}, `${pct} %`)));
}

function alarmsCell(s) {
  const a = s.alarms;
  if (!a || (!a.active && !a.unacknowledged)) return h('span', { class: 'muted' }, 'none');
  const items = (a.list || []).map((x) => h('li', {},
    h('span', { class: `badge severity-${x.severity}` }, x.severity), ` ${x.message}`,
    x.active ? '' : h('span', { class: 'muted' }, ' (cleared, not acknowledged)')));
  return h('div', { class: 'stand-alarms' },
    h('span', {}, `${a.active} active, ${a.unacknowledged} not acknowledged`), h('ul', { class: 'compact' }, ...items));
}

// The stand's reference equipment as its heartbeat judged it today: each instrument's due date,
// those overdue or due soon marked (the words are the daemon's, reference_equipment.hpp).
function equipmentCell(s) {
  const e = s.equipment;
  if (!e) return h('span', { class: 'muted' }, 'not reported');
  const items = ['table', 'chamber', 'gravity'].filter((k) => e[k]).map((k) => {
    const i = e[k];
    const cls = i.overdue ? 'result-bad' : i.due_soon ? 'warn-text' : '';
    return h('li', { class: cls, dataset: { instrument: k, overdue: String(!!i.overdue) } }, i.text || `${k}: due ${i.calibration_due}`);
  });
  if (!items.length) return h('span', { class: 'muted' }, 'none configured');
  return h('ul', { class: 'compact stand-equipment' }, ...items);
}

function standRow(s) {
  const online = h('span', { class: `badge ${s.online ? 'state-done' : 'state-failed'}`, 'data-online': String(s.online) },
    s.online ? 'online' : 'offline');
  return h('tr', { dataset: { stand: s.name, online: String(s.online) } },
    h('td', {}, standLink(s), h('div', { class: 'hint' }, `${s.bench}, imucal ${s.version}`)),
    h('td', {}, online, h('div', { class: 'hint', title: `registered ${dateTime(s.registered_at)}` }, `seen ${dateTime(s.last_seen)}`)),
    h('td', {}, runCell(s)),
    h('td', {}, alarmsCell(s)),
    h('td', {}, equipmentCell(s)));
}

export function mount(root) {
  const status = h('div', { class: 'form-error', role: 'alert', id: 'lab-error' });
  const body = h('tbody', { id: 'lab-rows' });
  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'Lab')),
    h('p', { class: 'hint' }, 'Every stand of the lab\'s registry, as its last heartbeat reported it. A stand not heard ',
      'from for three of its heartbeats shows offline. Its name leads to its own page.'),
    status,
    h('section', { class: 'card' },
      h('table', { class: 'list', id: 'lab-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'Stand'), h('th', {}, 'Status'), h('th', {}, 'Run'), h('th', {}, 'Alarms'),
          h('th', {}, 'Reference equipment'))),
        body)));

  let stopped = false;
  async function refresh() {
    try {
      const r = await get('/api/lab');
      if (stopped) return;
      status.textContent = '';
      clear(body).append(...r.stands.map(standRow));
      if (!r.stands.length) body.append(h('tr', {}, h('td', { colspan: 5, class: 'muted' }, 'No stand has registered yet.')));
    } catch (e) {
      if (!stopped) status.textContent = `Cannot read the lab's stands: ${e.message}`;
    }
  }
  refresh();
  const timer = setInterval(refresh, 3000);
  return () => {
    stopped = true;
    clearInterval(timer);
  };
}
