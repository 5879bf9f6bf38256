// Campaigns: what runs and waits (the queue), what was created and not started yet, and the
// history with state, duration and result. The page composes the bench card and three campaign
// tables (views/campaigns/); this module reads the list and sorts it into them.
import { get } from '../api.mjs';
import { h, dateTime, FINAL_STATES } from '../format.mjs';
import { isOperator } from '../session.mjs';
import { campaignTable } from './campaigns/campaign_table.mjs';
import { benchCard } from './campaigns/bench_card.mjs';

// Where a campaign that has not ended stands: whatever runs first, then the queue in its order,
// the interrupted ones last.
function rank(c) {
  if (c.queue_position !== null && c.queue_position !== undefined) return 10 + c.queue_position;
  if (c.state === 'interrupted') return 50000;
  return 0;  // running, paused, suspended, ...
}

export function mount(root, ctx) {
  const status = h('div', { class: 'form-error', role: 'alert' });
  const updated = h('span', { class: 'muted' });
  const active = campaignTable('active-campaigns');
  const created = campaignTable('created-campaigns');
  const history = campaignTable('history-campaigns');
  const activeEmpty = h('p', { class: 'muted empty-note', id: 'active-empty', hidden: true }, 'Nothing runs or waits. ',
    isOperator() ? h('a', { href: '#/new' }, 'Build a campaign') : 'An operator can start one.', '.');
  // Created but never started: not in the queue, so not under "Running and queued".
  const createdSection = h('section', { class: 'card', id: 'created-section', hidden: true }, h('h2', {}, 'Not started'),
    h('p', { class: 'muted' }, 'Created and waiting for an operator to start them (they are not in the queue).'),
    created.element);
  const historyEmpty = h('p', { class: 'muted empty-note', id: 'history-empty', hidden: true }, 'No finished campaigns yet.');
  // The first screen says what bench this is and what to do first (issue 36, item 9).
  const bench = benchCard(ctx);
  root.append(
    bench.element,
    h('div', { class: 'page-head' },
      h('h1', {}, 'Campaigns'),
      h('div', { class: 'actions' }, updated,
        h('a', { class: 'button primary operator-only', href: '#/new', id: 'new-campaign' }, 'New campaign'))),
    status,
    h('section', { class: 'card' }, h('h2', {}, 'Running and queued'), active.element, activeEmpty),
    createdSection,
    h('section', { class: 'card' }, h('h2', {}, 'History'), history.element, historyEmpty));

  function render(list) {
    const running = list.filter((c) => !FINAL_STATES.has(c.state) && c.state !== 'created')
      // the head of the queue first after whatever runs
      .sort((a, b) => rank(a) - rank(b) || a.id - b.id);
    const notStarted = list.filter((c) => c.state === 'created').sort((a, b) => a.id - b.id);
    const ended = list.filter((c) => FINAL_STATES.has(c.state));
    active.show(running);
    created.show(notStarted);
    createdSection.hidden = notStarted.length === 0;
    history.show(ended);
    // The steps until the first campaign has run here.
    bench.showFirstSteps(list.length === 0);
    activeEmpty.hidden = running.length > 0;
    historyEmpty.hidden = ended.length > 0;
  }

  let stopped = false;
  let inFlight = false;
  async function refresh() {
    if (stopped || inFlight) return;
    inFlight = true;
    try {
      const { campaigns } = await get('/api/campaigns?limit=200');
      status.textContent = '';
      render(campaigns || []);
      updated.textContent = `updated ${dateTime(new Date().toISOString()).slice(11)}`;
    } catch (e) {
      status.textContent = `Cannot load the campaigns: ${e.message}`;
    } finally {
      inFlight = false;
    }
  }

  refresh();
  const timer = setInterval(refresh, 4000);
  // A state change anywhere shows at once, not at the next poll.
  let soon = null;
  const onEvent = (ev) => {
    if (ev.detail.kind !== 'transition') return;
    clearTimeout(soon);
    soon = setTimeout(refresh, 150);
  };
  ctx.store.addEventListener('event', onEvent);
  return () => {
    stopped = true;
    clearInterval(timer);
    clearTimeout(soon);
    ctx.store.removeEventListener('event', onEvent);
    bench.destroy();
  };
}
