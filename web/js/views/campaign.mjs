// One campaign: its state and commands while it runs, and its results when it is done: the
// coefficient table with sigmas (with the truth and the error in simulated runs), the estimators'
// convergence, the Allan, thermal and Schuler-test plots imucald computes from the recording (or
// what the run would need for them), the downloads
// (model JSON, recording bundle, printable certificate), and the record of what happened.
// Each part is a component of views/campaign/; this module reads the campaign, polls it while it
// runs and hands each part its data.
import { get, ApiError } from '../api.mjs';
import { h, clear, outcomeBadge, FINAL_STATES } from '../format.mjs';
import { commandBar } from '../dialogs.mjs';
import { campaignFacts } from './campaign/campaign_facts.mjs';
import { resultsCard } from './campaign/results_card.mjs';
import { recordCard } from './campaign/record_card.mjs';

export function mount(root, ctx) {
  const id = ctx.params.id;
  let detail = null;
  let stopped = false;
  let timer = null;
  let resultsFor = null;  // the state for which the results were loaded
  const cleanups = [];

  const title = h('h1', { id: 'campaign-title' }, `Campaign ${id}`);
  const badge = h('span', { id: 'campaign-state' });
  const pageError = h('div', { class: 'form-error', role: 'alert', id: 'campaign-error' });
  const onError = (text) => { pageError.textContent = text; };
  const commands = commandBar({
    getCampaign: () => detail && { id: detail.id, name: detail.name, state: detail.state },
    onDone: () => refresh(),
  });
  const facts = campaignFacts();
  const results = resultsCard({
    id, status: () => ctx.status(), getDetail: () => detail, isStopped: () => stopped, onError, cleanups,
    // An accepted partial run has a certificate now: its results are drawn again.
    onAccepted: async () => {
      resultsFor = null;
      await refresh();
    },
  });
  const record = recordCard({ id, refresh: () => refresh(), onError });
  root.append(
    h('div', { class: 'page-head' }, h('div', { class: 'title-line' }, title, badge), commands),
    pageError, facts.element, results.element, record.element);

  async function refresh() {
    if (stopped) return;
    try {
      const d = await get(`/api/campaigns/${id}`);
      if (stopped) return;
      detail = d;
      pageError.textContent = '';
      render();
      const final = FINAL_STATES.has(d.state);
      if (final && resultsFor !== d.state) {
        resultsFor = d.state;
        results.load(detail);
      } else if (!final && !resultsFor && Object.keys(d.results || {}).length) {
        resultsFor = 'partial';
        results.load(detail);
      }
      if (final) clearInterval(timer);
    } catch (e) {
      pageError.textContent = e instanceof ApiError && e.status === 404 ? `There is no campaign ${id}.` : `Cannot load campaign ${id}: ${e.message}`;
    }
  }

  function render() {
    const d = detail;
    title.textContent = `Campaign ${d.id}: ${d.name}`;
    document.title = `imucal · ${d.name}`;
    clear(badge).append(outcomeBadge(d));
    commands.update();
    facts.show(d);
    record.show(d);
  }

  // ---- the live strip while this campaign is the active run ----

  const onTelemetry = (ev) => {
    const run = ev.detail.run;
    const mine = run && run.id === id;
    facts.showLive(mine ? run : null);
    if (!mine) return;
    // A telemetry tick can be older than the last read of the campaign: it never takes an ended
    // run back to a live state (the run's own events read it again), and it changes a copy, never
    // the object the results were drawn from (their downloads were drawn for the state it had).
    if (detail && run.state !== detail.state && !FINAL_STATES.has(detail.state)) {
      detail = { ...detail, state: run.state };
      clear(badge).append(outcomeBadge({ state: run.state }));
      commands.update();
    }
  };
  const onEvent = (ev) => {
    if (ev.detail.campaign === id) refresh();
  };
  const onAlarm = (ev) => {
    if (ev.detail.alarm?.campaign === id) refresh();
  };
  ctx.store.addEventListener('telemetry', onTelemetry);
  ctx.store.addEventListener('event', onEvent);
  ctx.store.addEventListener('alarm', onAlarm);

  refresh();
  timer = setInterval(refresh, 2000);
  return () => {
    stopped = true;
    clearInterval(timer);
    ctx.store.removeEventListener('telemetry', onTelemetry);
    ctx.store.removeEventListener('event', onEvent);
    ctx.store.removeEventListener('alarm', onAlarm);
    for (const c of cleanups) c();
    document.title = 'imucal';
  };
}
