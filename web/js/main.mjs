// The imucal single-page UI: a hash router over the views, the header (who is signed in, the live
// connection, the active run), and the one WebSocket the page keeps open. Views are modules with
// mount(root, ctx) returning a cleanup function.
import { get, ApiError } from './api.mjs';
import { loadSchema, schemaLoaded } from './schema.mjs';
import { session, checkSession, signOut, onSessionChange, isOperator } from './session.mjs';
import { LiveClient, LiveStore } from './live.mjs';
import { applyAlarm, alarmSummary } from './alarms.mjs';
import { alarmTable, acknowledgeAlarm } from './alarm_panel.mjs';
import { h, clear, duration, stateBadge } from './format.mjs';
import * as signinView from './views/signin.mjs';
import * as campaignsView from './views/campaigns.mjs';
import * as builderView from './views/builder.mjs';
import * as liveView from './views/live.mjs';
import * as campaignView from './views/campaign.mjs';
import * as unitView from './views/unit.mjs';
import * as unitsView from './views/units.mjs';
import * as auditView from './views/audit.mjs';
import * as labView from './views/lab.mjs';

const viewRoot = document.getElementById('view');
const banner = document.getElementById('banner');
const alerts = document.getElementById('alerts');
const alarmPanel = document.getElementById('alarm-panel');

const live = new LiveClient();
const store = new LiveStore();
live.addEventListener('message', (ev) => store.ingest(ev.detail));

let statusCache = null;
const ctx = {
  live,
  store,
  navigate: (hash) => { location.hash = hash; },
  /** GET /api/status, cached for the session (limits, site, estimators); `fresh` refetches. */
  async status(fresh = false) {
    if (!statusCache || fresh) statusCache = get('/api/status').catch((e) => { statusCache = null; throw e; });
    return statusCache;
  },
};
// A handle for the browser tests and for debugging from the console.
window.imucal = { live, store, session, ctx };

const routes = [
  { re: /^#\/signin$/, view: signinView, nav: null, public: true },
  { re: /^#\/campaigns\/(\d+)$/, view: campaignView, nav: 'campaigns', params: (m) => ({ id: Number(m[1]) }) },
  { re: /^#\/campaigns\/?$/, view: campaignsView, nav: 'campaigns' },
  { re: /^#\/new(?:\/([\w.-]+))?$/, view: builderView, nav: 'new', params: (m) => ({ template: m[1] || null }) },
  { re: /^#\/live$/, view: liveView, nav: 'live' },
  { re: /^#\/imus\/?$/, view: unitsView, nav: 'units' },
  { re: /^#\/imus\/([^/]+)$/, view: unitView, nav: 'units', params: (m) => ({ serial: decodeURIComponent(m[1]) }) },
  { re: /^#\/audit\/?$/, view: auditView, nav: 'audit' },
  { re: /^#\/lab\/?$/, view: labView, nav: 'lab' },
];

let unmount = null;
let afterSignIn = '#/campaigns';

function route() {
  const hash = location.hash || '#/campaigns';
  let match = null, found = null;
  for (const r of routes) {
    match = r.re.exec(hash);
    if (match) { found = r; break; }
  }
  if (!found) {
    location.replace('#/campaigns');
    return;
  }
  if (!found.public && !session.user) {
    afterSignIn = hash;
    location.replace('#/signin');
    return;
  }
  // The pages name coefficients by imucald's schema (schema.mjs), readable once signed in: asked
  // for before the first page that needs it, then the route taken again.
  if (!found.public && !schemaLoaded()) {
    waitForSchema();
    return;
  }
  if (unmount) {
    try { unmount(); } catch (e) { console.error(e); }
    unmount = null;
  }
  for (const a of document.querySelectorAll('#nav a')) a.classList.toggle('active', a.dataset.nav === found.nav);
  clear(viewRoot);
  viewRoot.dataset.view = found.nav || 'signin';
  const params = found.params ? found.params(match) : {};
  const local = { ...ctx, params, afterSignIn: () => afterSignIn };
  unmount = found.view.mount(viewRoot, local) || null;
  window.scrollTo(0, 0);
}

// One request at a time; when it answers, the route of the hash then current is taken.
let schemaWaiting = false;
function waitForSchema() {
  if (schemaWaiting) return;
  schemaWaiting = true;
  loadSchema(get).then(() => {
    schemaWaiting = false;
    route();
  }, (e) => {
    clear(viewRoot).append(h('p', { class: 'form-error', id: 'schema-error' }, `Cannot load the coefficients' names from imucald: ${e.message} Retrying in 3 s…`));
    setTimeout(() => { schemaWaiting = false; route(); }, 3000);
  });
}

// ---- header -------------------------------------------------------------------------------------

function renderWho() {
  const who = document.getElementById('who');
  clear(who);
  if (!session.user) return;
  who.append(
    h('span', { class: `role role-${session.role}`, title: session.role === 'viewer' ? 'A viewer sees everything and changes nothing' : 'May start and stop campaigns' },
      `${session.user} · ${session.role}`),
    h('button', { type: 'button', class: 'link', id: 'signout', onclick: async () => {
      live.stop();
      await signOut();
      location.hash = '#/signin';
    } }, 'Sign out'));
}

let bannerTimer = null;
function showBanner(kind, text, hideAfterMs = 0) {
  clearTimeout(bannerTimer);
  banner.hidden = !text;
  banner.className = `banner banner-${kind}`;
  banner.dataset.kind = kind;
  banner.textContent = text || '';
  if (hideAfterMs) bannerTimer = setTimeout(() => { banner.hidden = true; banner.dataset.kind = ''; }, hideAfterMs);
}

live.addEventListener('status', (ev) => {
  const s = ev.detail;
  const ind = document.getElementById('live-indicator');
  ind.dataset.state = s.state;
  const labels = { idle: 'live: —', connecting: 'live: connecting', open: 'live: connected', waiting: 'live: lost', signin: 'live: sign in again', stopped: 'live: off' };
  ind.textContent = labels[s.state] || s.state;
  if (s.state === 'signin') {
    showBanner('warn', 'Your session has ended, so imucald closed the live connection. Sign in again to continue; the page keeps what you entered.');
  } else if (s.state === 'waiting' && s.lostAt) {
    const secs = Math.ceil(s.retryInMs / 1000);
    showBanner('warn', `Live connection lost ${duration((Date.now() - s.lostAt) / 1000)} ago — reconnecting ${secs > 0 ? `in ${secs} s` : 'now'} (attempt ${s.attempt}). Plots and states resume when it is back.`);
  } else if (s.state === 'waiting' && !s.everOpened) {
    showBanner('warn', `Cannot open the live connection — retrying (attempt ${s.attempt}).`);
  } else if (s.state === 'open' && s.restoredAfterMs != null) {
    showBanner('ok', `Live connection restored after ${duration(s.restoredAfterMs / 1000)}.`, 6000);
  } else if (s.state === 'open' && banner.dataset.kind === 'warn') {
    showBanner('ok', 'Live connection open.', 3000);
  }
});

function renderRunChip(m) {
  const chip = document.getElementById('run-chip');
  const run = m?.run;
  if (!run) {
    chip.hidden = true;
    return;
  }
  chip.hidden = false;
  clear(chip);
  const pct = run.duration_s > 0 ? Math.min(100, (100 * run.program_time_s) / run.duration_s) : 0;
  chip.append(h('a', { href: '#/live', title: 'Open the live view' }, `#${run.id} ${run.name}`), ' ', stateBadge(run.state),
    h('span', { class: 'chip-progress' }, ` ${pct.toFixed(0)} %`));
}
let chipState = '';
store.addEventListener('telemetry', (ev) => {
  const run = ev.detail.run;
  // Only touch the DOM when something shown changed (10 messages a second).
  const key = run ? `${run.id}|${run.state}|${Math.floor((100 * run.program_time_s) / (run.duration_s || 1))}` : '';
  if (key !== chipState) {
    chipState = key;
    renderRunChip(ev.detail);
  }
});

// Alarms, suspensions and failures as they happen, wherever the user is: bottom right, clear of
// the controls. A suspension's notice says when the run resumed and then goes away by itself; the
// others stay until dismissed. These are notices only: the alarm list under the header keeps
// every alarm until an operator has acknowledged it.
const ALERT_KINDS = new Set(['suspended', 'alarm', 'error', 'interrupted']);
store.addEventListener('event', (ev) => {
  const e = ev.detail;
  if (e.kind === 'resumed' || (e.kind === 'transition' && e.from === 'suspended' && e.to === 'running')) {
    for (const item of alerts.querySelectorAll(`.alert-suspended[data-campaign="${e.campaign}"]:not(.resolved)`)) {
      item.classList.add('resolved');
      item.append(h('div', { class: 'resolved-note' }, `resumed: ${e.reason || 'condition cleared'}`));
      setTimeout(() => item.remove(), 8000);
    }
    return;
  }
  // The transition into `suspended` comes with a `suspended` event giving the same reason.
  const serious = ALERT_KINDS.has(e.kind) || (e.kind === 'transition' && ['failed', 'interrupted'].includes(e.to));
  if (!serious) return;
  const kind = e.kind === 'transition' ? e.to : e.kind;
  const what = e.kind === 'transition' ? `campaign ${e.campaign}: ${e.from} → ${e.to}` : `campaign ${e.campaign}: ${e.kind}`;
  const item = h('div', { class: `alert alert-${kind}`, role: 'alert', dataset: { campaign: e.campaign, kind } },
    h('button', { type: 'button', class: 'link dismiss', 'aria-label': 'dismiss', onclick: () => item.remove() }, '×'),
    h('strong', {}, what), e.reason ? ` — ${e.reason}` : '');
  alerts.prepend(item);
  while (alerts.children.length > 4) alerts.lastChild.remove();
});

// The alarms that need someone (docs/api.md "Alarms"), on every page until acknowledged: active
// ones and cleared ones nobody has acknowledged yet (styled apart). Loaded at sign-in and whenever
// the live connection (re)opens, then kept up to date by its alarm messages.
let alarmList = [];
let alarmError = '';
async function loadAlarms() {
  if (!session.user) return;
  try {
    alarmList = (await get('/api/alarms')).alarms || [];
    alarmError = '';
  } catch (e) {
    alarmError = `Cannot load the alarms: ${e.message}`;
  }
  renderAlarms();
}
function renderAlarms() {
  clear(alarmPanel);
  alarmPanel.hidden = !session.user || (!alarmList.length && !alarmError);
  if (alarmPanel.hidden) return;
  const onAcknowledged = (a) => {
    alarmList = applyAlarm(alarmList, a);
    alarmError = '';
    renderAlarms();
  };
  const onError = (a, e) => {
    alarmError = `Alarm ${a.id}: ${e.message}`;
    loadAlarms();
  };
  alarmPanel.dataset.active = String(alarmList.some((a) => !a.cleared));
  // After a night of chamber excursions: one click for every alarm the operator has read. Each is
  // acknowledged on its own (the daemon keeps who and when per alarm); a refusal (acknowledged
  // meanwhile by someone else) is shown and the list reloaded.
  const waiting = alarmList.filter((a) => !a.acknowledged);
  let all = null;
  if (waiting.length >= 2) {
    const operator = isOperator();
    all = h('button', { type: 'button', id: 'alarm-ack-all', disabled: !operator,
      title: operator ? `Acknowledge the ${waiting.length} alarms listed (your name and the time are kept for each)` : 'operator role required (you are signed in as a viewer)' },
    `Acknowledge all ${waiting.length}`);
    all.addEventListener('click', async () => {
      all.disabled = true;
      for (const a of waiting) {
        try {
          alarmList = applyAlarm(alarmList, await acknowledgeAlarm(a));
        } catch (e) {
          onError(a, e);
          return;
        }
      }
      alarmError = '';
      renderAlarms();
    });
  }
  // Element.append writes null as the text "null": only the parts there are.
  alarmPanel.append(...[
    h('div', { class: 'alarm-head' }, h('strong', { id: 'alarm-summary' }, alarmList.length ? alarmSummary(alarmList) : 'Alarms'), all),
    alarmError ? h('div', { class: 'form-error', role: 'alert', id: 'alarm-error' }, alarmError) : null,
    alarmList.length ? alarmTable(alarmList, { id: 'alarm-list', onAcknowledged, onError }) : null,
  ].filter(Boolean));
}
store.addEventListener('alarm', (ev) => {
  if (!ev.detail.alarm) return;
  alarmList = applyAlarm(alarmList, ev.detail.alarm);
  renderAlarms();
});
// Messages missed while the connection was down: the list is asked for again.
live.addEventListener('status', (ev) => {
  if (ev.detail.state === 'open') loadAlarms();
});

// ---- start --------------------------------------------------------------------------------------

onSessionChange(() => {
  renderWho();
  if (session.user) {
    live.start();
    loadAlarms();
  } else {
    alarmList = [];
    renderAlarms();
  }
});

async function boot() {
  for (;;) {
    try {
      await checkSession();
      break;
    } catch (e) {
      const msg = e instanceof ApiError ? e.message : String(e);
      clear(viewRoot).append(h('p', { class: 'form-error' }, `${msg} Retrying in 3 s…`));
      await new Promise((r) => setTimeout(r, 3000));
    }
  }
  window.addEventListener('hashchange', route);
  route();
}

boot();
