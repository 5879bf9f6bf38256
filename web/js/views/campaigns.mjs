// Campaigns: what runs and waits (the queue), what was created and not started yet, and the
// history with state, duration and result.
import { get } from '../api.mjs';
import { h, clear, duration, dateTime, outcomeBadge, FINAL_STATES } from '../format.mjs';
import { isOperator } from '../session.mjs';
import { benchSummary } from '../bench.mjs';

export function mount(root, ctx) {
  const status = h('div', { class: 'form-error', role: 'alert' });
  const activeBody = h('tbody');
  const createdBody = h('tbody');
  const historyBody = h('tbody');
  const updated = h('span', { class: 'muted' });
  const table = (body, id) => h('table', { class: 'list', id },
    h('thead', {}, h('tr', {},
      h('th', { class: 'num' }, '#'), h('th', {}, 'Name'), h('th', {}, 'Unit'), h('th', {}, 'Program'), h('th', {}, 'State'),
      h('th', {}, 'Created'), h('th', {}, 'Started'), h('th', { class: 'num' }, 'Program length'),
      h('th', { class: 'num' }, 'Wall time'), h('th', {}, 'Progress / result'))),
    body);

  // The first screen says what bench this is and what to do first (issue 36, item 9).
  const bench = h('section', { class: 'card bench-card', id: 'bench' });
  const firstSteps = h('ol', { class: 'first-steps', id: 'first-steps', hidden: true });
  root.append(
    bench,
    h('div', { class: 'page-head' },
      h('h1', {}, 'Campaigns'),
      h('div', { class: 'actions' }, updated,
        h('a', { class: 'button primary operator-only', href: '#/new', id: 'new-campaign' }, 'New campaign'))),
    status,
    h('section', { class: 'card' }, h('h2', {}, 'Running and queued'), table(activeBody, 'active-campaigns'),
      h('p', { class: 'muted empty-note', id: 'active-empty', hidden: true }, 'Nothing runs or waits. ',
        isOperator() ? h('a', { href: '#/new' }, 'Build a campaign') : 'An operator can start one.', '.')),
    // Created but never started: not in the queue, so not under "Running and queued".
    h('section', { class: 'card', id: 'created-section', hidden: true }, h('h2', {}, 'Not started'),
      h('p', { class: 'muted' }, 'Created and waiting for an operator to start them (they are not in the queue).'),
      table(createdBody, 'created-campaigns')),
    h('section', { class: 'card' }, h('h2', {}, 'History'), table(historyBody, 'history-campaigns'),
      h('p', { class: 'muted empty-note', id: 'history-empty', hidden: true }, 'No finished campaigns yet.')));

  let timer = null;
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

  function render(list) {
    const active = list.filter((c) => !FINAL_STATES.has(c.state) && c.state !== 'created')
      // the head of the queue first after whatever runs
      .sort((a, b) => rank(a) - rank(b) || a.id - b.id);
    const created = list.filter((c) => c.state === 'created').sort((a, b) => a.id - b.id);
    const history = list.filter((c) => FINAL_STATES.has(c.state));
    clear(activeBody).append(...active.map(row));
    clear(createdBody).append(...created.map(row));
    root.querySelector('#created-section').hidden = created.length === 0;
    clear(historyBody).append(...history.map(row));
    // The steps until the first campaign has run here.
    firstSteps.hidden = list.length > 0;
    root.querySelector('#active-empty').hidden = active.length > 0;
    root.querySelector('#history-empty').hidden = history.length > 0;
  }

  function rank(c) {
    if (c.queue_position !== null && c.queue_position !== undefined) return 10 + c.queue_position;
    if (c.state === 'interrupted') return 50000;
    return 0;  // running, paused, suspended, ...
  }

  function row(c) {
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
      h('td', {}, result(c)));
  }

  function result(c) {
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

  let daemonStatus = null;
  function drawBench() {
    if (stopped || !daemonStatus) return;
    const b = benchSummary(daemonStatus, ctx.store.latest);
    const sig = JSON.stringify(b);
    if (bench.dataset.sig === sig) return;
    bench.dataset.sig = sig;
    bench.dataset.simulated = String(b.simulated);
    const steps = isOperator()
      ? [[h('a', { href: '#/new' }, 'New campaign'), ': start from a built-in program (', h('code', {}, 'direct-short'),
        ' is a quick first calibration: stage 1 in a few minutes of program), name the unit under test',
        b.simulated ? ' and choose the simulated IMU\'s truth' : '', '. The builder checks it with imucald and predicts its accuracy.'],
      ['"Create and start…": ', b.simulated ? 'the simulated table moves' : 'the table moves as soon as the devices are free',
        '; watch it on ', h('a', { href: '#/live' }, 'Live'), ' (pause, stop, abort there).'],
      ['When it is done, its page here has the results, the model, the certificate and the test report; ',
        h('a', { href: '#/imus' }, 'Units'), ' keeps each unit\'s calibrations and the acceptance limits.']]
      : [['You are signed in as a viewer: you can watch runs on ', h('a', { href: '#/live' }, 'Live'),
        ' and read every result; an operator builds and starts campaigns.']];
    clear(firstSteps).append(...steps.map((s) => h('li', {}, ...s)));
    clear(bench).append(
      h('h2', {}, `${b.title}${b.site ? ` — ${b.site}` : ''}`),
      h('p', { class: 'bench-text' }, b.text),
      h('ul', { class: 'bench-devices', id: 'bench-devices' }, ...b.devices.map((d) =>
        h('li', { dataset: { device: d.name, state: d.state } }, h('strong', {}, d.name), ' ', h('span', { class: `flag ${['ok', 'warn', 'bad'].includes(d.state) ? d.state : ''}` }, d.text)))),
      h('h3', {}, 'What to do first'), firstSteps);
  }
  ctx.status().then((s) => { daemonStatus = s; drawBench(); }).catch((e) => { bench.textContent = `Cannot read imucald's status: ${e.message}`; });
  // Connected or not, as the telemetry says (10 a second; the card is redrawn only on a change).
  const onTelemetry = () => drawBench();
  ctx.store.addEventListener('telemetry', onTelemetry);

  refresh();
  timer = setInterval(refresh, 4000);
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
    ctx.store.removeEventListener('telemetry', onTelemetry);
  };
}
