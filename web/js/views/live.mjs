// The live view: the active run (step, time left, commands), table, chamber, IMU and recorder
// readings, their plots, the estimators converging, and alarms and suspensions as they happen.
// Everything comes from the page's one WebSocket through the LiveStore; this view only draws,
// once per animation frame at most.
import { get, post } from '../api.mjs';
import { isOperator } from '../session.mjs';
import { h, clear, duration, num, fixed, stateBadge, timeOfDay } from '../format.mjs';
import { lineChart, schedule, AXIS_COLORS, COLORS } from '../plots.mjs';
import { commandBar } from '../dialogs.mjs';
import { convergencePanel } from '../convergence.mjs';
import { unitOf } from '../coefficients.mjs';
import { AXES } from '../live.mjs';
import { pauseNote } from '../outcome.mjs';
import { recordingPlots } from '../recording_plots.mjs';
import { equipmentWarnings } from '../equipment.mjs';

const WINDOWS = [['60', '1 min'], ['600', '10 min'], ['3600', '1 h'], ['Infinity', 'whole run']];

// Where the run is: its step, or, once the program has ended ahead of the estimators (a fast time
// scale), that they are finishing the rest of the recording.
function runStepText(run) {
  const seg = run.segment || {};
  return run.estimators_finishing ? 'The program has ended; the estimators are working through the rest of the recording, then its results are stored.'
    : `step ${seg.index + 1} of ${seg.count}: ${seg.name} (${seg.kind})`;
}

export function mount(root, ctx) {
  const { store } = ctx;
  let windowS = Number(localStorage.getItem('imucal.live.window') || 600);
  if (!Number.isFinite(windowS) && windowS !== Infinity) windowS = 600;

  const runBox = h('section', { class: 'card run-card', id: 'run-card' });
  const suspendedBanner = h('div', { class: 'suspended-banner', id: 'suspended-banner', role: 'alert', hidden: true });
  // A paused run says who paused it and how it goes on (its transitions, asked once per pause).
  const pausedBanner = h('div', { class: 'suspended-banner paused-banner', id: 'paused-banner', role: 'status', hidden: true });
  let pauseFor = '';
  let pauseTransitions = null;
  // What the run asks the operator (a power cycle of the IMU): it waits for the answer.
  const promptText = h('p', { id: 'prompt-text' });
  const promptError = h('div', { class: 'form-error', id: 'prompt-error', role: 'alert' });
  const promptDone = h('button', { type: 'button', class: 'primary', id: 'prompt-done' }, 'Done: the IMU is on again');
  const promptBox = h('div', { class: 'prompt-box', id: 'prompt-box', role: 'alert', hidden: true },
    h('strong', {}, 'The run waits for you'), promptText, promptDone, promptError);
  let promptRun = null;
  promptDone.addEventListener('click', async () => {
    if (promptRun === null) return;
    promptDone.disabled = true;
    promptError.textContent = '';
    try {
      await post(`/api/campaigns/${promptRun}/prompt`, { answer: 'done' });
    } catch (e) {
      promptError.textContent = `The answer was not taken: ${e.message}`;
      promptDone.disabled = !isOperator();
    }
  });
  const runTitle = h('h1', { id: 'run-title' });
  const runState = h('span', { id: 'run-state' });
  const stepText = h('div', { class: 'kv', id: 'run-step' });
  const timeText = h('div', { class: 'kv', id: 'run-time' });
  const leftText = h('div', { class: 'kv', id: 'run-left' });
  const speedText = h('div', { class: 'kv', id: 'run-speed' });
  const progress = h('div', { class: 'progress wide', id: 'run-progress' }, h('div', { class: 'bar' }), h('span', {}));
  // The run that ended, kept with its plots and convergence until another starts (issue 36).
  const finishedBox = h('p', { class: 'finished-run', id: 'finished-run', hidden: true });
  let current = null;  // {id, name, state} of the run shown
  const commands = commandBar({
    getCampaign: () => current,
    onDone: () => schedule(drawNumbers),
  });
  runBox.append(
    h('div', { class: 'run-head' }, runTitle, runState, h('div', { class: 'spacer' }), commands),
    suspendedBanner, pausedBanner, promptBox, finishedBox,
    h('div', { class: 'run-facts' }, stepText, timeText, leftText, speedText), progress);

  const cards = h('div', { class: 'cards' });
  const cell = (id) => h('span', { class: 'value', id });
  const kv = (label, id, unit = '') => h('div', { class: 'kv' }, h('span', { class: 'label' }, label), cell(id), unit ? h('span', { class: 'unit' }, unit) : null);
  cards.append(
    h('section', { class: 'card small', id: 'table-card' }, h('h2', {}, 'Table'),
      h('table', { class: 'axes' }, h('thead', {}, h('tr', {}, h('th', {}, ''), h('th', { class: 'num' }, 'angle °'), h('th', { class: 'num' }, 'rate °/s'))),
        h('tbody', {}, ...AXES.map((a) => h('tr', {}, h('th', { style: `color:${AXIS_COLORS[a]}` }, a), h('td', { class: 'num', id: `angle-${a}` }), h('td', { class: 'num', id: `rate-${a}` }))))),
      h('div', { class: 'flags', id: 'table-flags' }),
      h('p', { class: 'map-note', id: 'table-dialect', hidden: true })),
    h('section', { class: 'card small', id: 'chamber-card' }, h('h2', {}, 'Chamber'),
      kv('temperature', 'chamber-temp', '°C'), kv('set point', 'chamber-sp', '°C'), kv('tolerance', 'chamber-tol', '± °C'),
      h('div', { class: 'flags', id: 'chamber-flags' }),
      h('p', { class: 'map-note', id: 'chamber-map', hidden: true })),
    h('section', { class: 'card small', id: 'imu-card' }, h('h2', {}, 'IMU and recorder'),
      kv('frame rate', 'imu-rate', 'Hz'), kv('frames', 'imu-frames'), kv('lost', 'imu-lost'), kv('bad', 'imu-bad'),
      kv('recorder queue', 'rec-queue', 'frames'), kv('committed', 'rec-committed', 'frames'),
      h('div', { class: 'flags', id: 'imu-flags' })),
    h('section', { class: 'card small', id: 'estimators-card' }, h('h2', {}, 'Estimators'), h('div', { id: 'estimator-status' })));

  // Reference equipment past its due date or due within a week (GET /api/status
  // reference_equipment, judged today by imucald): a campaign will not start without an override.
  const equipmentBanner = h('div', { class: 'equipment-banner', id: 'equipment-banner', role: 'alert', hidden: true });
  // The chamber controller's register map, and whether the maker's manual vouches for it; the
  // table controller's dialect and what it was written from (GET /api/status chamber_map and
  // table_dialect; none on the in-process simulation). Asked afresh: the due dates are today's.
  const showDueDates = (s) => {
    const warnings = equipmentWarnings(s?.reference_equipment);
    equipmentBanner.replaceChildren(...(warnings ? [
      ...warnings.lines.map((w) => h('p', { class: w.overdue ? 'overdue' : 'due-soon', dataset: { instrument: w.instrument } }, w.text)),
      h('p', { class: 'consequence' }, warnings.sentence)] : []));
    equipmentBanner.classList.toggle('overdue', Boolean(warnings?.overdue));
    equipmentBanner.hidden = !warnings;
  };
  // A live page left open over days (an unattended night, a weekend) asks again every hour.
  const dueDatesTimer = setInterval(() => ctx.status(true).then(showDueDates).catch(() => {}), 3600 * 1000);
  ctx.status(true).then((s) => {
    showDueDates(s);
    const td = s?.table_dialect;
    const tel = cards.querySelector('#table-dialect');
    if (td && tel) {
      tel.textContent = `Dialect ${td.name}`;
      tel.title = td.source;
      tel.hidden = false;
    }
    const cm = s?.chamber_map;
    const el = cards.querySelector('#chamber-map');
    if (!cm || !el) return;
    el.textContent = `Register map ${cm.name}: ${cm.summary}.`;
    el.dataset.checked = cm.checked;
    if (cm.checked !== 'yes') el.classList.add('warn-text');
    el.hidden = false;
  }).catch(() => {});

  const windowSel = h('div', { class: 'tabs small', role: 'tablist', id: 'window-tabs' },
    ...WINDOWS.map(([v, label]) => h('button', { type: 'button', role: 'tab', dataset: { window: v }, 'aria-selected': String(Number(v) === windowS),
      onclick: () => {
        windowS = Number(v);
        localStorage.setItem('imucal.live.window', v);
        for (const b of windowSel.children) b.setAttribute('aria-selected', String(b.dataset.window === v));
        wholeRunMode();
        schedule(drawPlots);
      } }, label)));
  const plotGrid = h('div', { class: 'plot-grid' });
  const plotBox = (id) => h('div', { class: 'plot', id });
  const anglesEl = plotBox('plot-angles'), ratesEl = plotBox('plot-rates'), chamberEl = plotBox('plot-chamber'), rateEl = plotBox('plot-imu-rate');
  plotGrid.append(anglesEl, ratesEl, chamberEl, rateEl);
  // "Whole run": the run's recording so far, read from imucald (it survives a reload, which the
  // page's own buffers do not), over program time, read again every 10 s.
  const recordingBox = h('div', { class: 'recording-plots', id: 'live-recording', hidden: true });
  let recording = null, recordingRun = null;
  function wholeRunMode() {
    const whole = windowS === Infinity && store.runId !== null;
    plotGrid.hidden = whole;
    recordingBox.hidden = !whole;
    if (whole && recordingRun === store.runId) return;
    recording?.();
    recording = null;
    recordingRun = null;
    recordingBox.replaceChildren();
    if (whole) {
      recording = recordingPlots(recordingBox, store.runId);
      recordingRun = store.runId;
    }
  }
  const recordingTimer = setInterval(() => recording?.reload(), 10000);

  const convEl = h('div', { id: 'convergence' });
  // Which estimator's convergence is shown: the operator's pick, else the one running now.
  const convPick = h('div', { class: 'tabs small', role: 'tablist', id: 'conv-estimator' });
  let pickedEstimator = null;
  const innovationsCard = h('section', { class: 'card', id: 'innovations-card', hidden: true },
    h('h2', {}, 'Stage 3: innovations against their gates'),
    h('p', { class: 'muted', id: 'innovations-note' }),
    h('div', { class: 'conv-grid', id: 'innovations' }));
  const eventsBody = h('tbody', { id: 'events' });
  root.append(equipmentBanner, runBox, cards,
    h('section', { class: 'card' }, h('div', { class: 'section-head' }, h('h2', {}, 'Table, chamber and IMU'), windowSel), plotGrid, recordingBox),
    h('section', { class: 'card' }, h('div', { class: 'section-head' }, h('h2', {}, 'Estimators converging (estimate ± σ over program time)'), convPick), convEl),
    innovationsCard,
    h('section', { class: 'card' }, h('h2', {}, 'Events, alarms and suspensions'),
      h('table', { class: 'list events' }, h('thead', {}, h('tr', {}, h('th', {}, 'time'), h('th', {}, 'campaign'), h('th', {}, 'event'), h('th', {}, 'reason'))), eventsBody),
      h('p', { class: 'muted', id: 'events-empty' }, 'Nothing has happened since this page connected.')));

  const height = 150;  // four plots and the run above them on a 768-pixel screen
  const angles = lineChart(anglesEl, { height, title: 'Table angles', y: '°', series: AXES.map((a) => ({ label: a, color: AXIS_COLORS[a] })) });
  const rates = lineChart(ratesEl, { height, title: 'Table rates', y: '°/s', series: AXES.map((a) => ({ label: a, color: AXIS_COLORS[a] })) });
  const chamber = lineChart(chamberEl, { height, title: 'Chamber temperature against set point', y: '°C',
    series: [{ label: 'temperature', color: COLORS[1] }, { label: 'set point', color: '#444', dash: [6, 4] },
      { label: '−tol', band: true }, { label: '+tol', band: true }],
    bands: [[4, 3, 'rgba(46,125,50,0.12)']] });
  const frameRate = lineChart(rateEl, { height, title: 'IMU frame rate', y: 'Hz', series: [{ label: 'frames/s', color: COLORS[3] }] });
  // The estimator whose convergence is shown (those with estimates: direct, lever-arm, stage3).
  function shownEstimator() {
    const withEstimates = [...store.estimators.entries()].filter(([, e]) => e.coefficients.size > 0).map(([n]) => n);
    if (pickedEstimator && withEstimates.includes(pickedEstimator)) return pickedEstimator;
    const running = withEstimates.filter((n) => store.estimators.get(n).latest?.status === 'running');
    return running.length ? running[running.length - 1] : withEstimates[withEstimates.length - 1] || null;
  }
  // A draw scheduled for the next frame may come after the view was left (its elements gone).
  let destroyed = false;

  function drawPick() {
    if (destroyed) return;
    const names = [...store.estimators.entries()].filter(([, e]) => e.coefficients.size > 0).map(([n]) => n);
    const shown = shownEstimator();
    const sig = `${names.join('|')}/${shown}`;
    if (convPick.dataset.sig === sig) return;
    if (convPick.dataset.shown !== undefined && convPick.dataset.shown !== String(shown)) conv.rebuild();
    convPick.dataset.sig = sig;
    convPick.dataset.shown = String(shown);
    clear(convPick).append(...(names.length > 1 ? names : []).map((n) => h('button', {
      type: 'button', role: 'tab', dataset: { estimator: n }, 'aria-selected': String(n === shown),
      onclick: () => { pickedEstimator = n; drawPick(); } }, n)));
  }
  const restartsOf = (name) => store.estimators.get(name)?.restarts || [];
  const conv = convergencePanel(convEl, () => {
    const name = shownEstimator();
    return name ? store.estimators.get(name).coefficients : new Map();
  }, { idPrefix: 'live-conv', markers: () => restartsOf(shownEstimator()) });

  // Stage 3's innovations: one small chart per measured quantity, its ±gate as a band, the
  // navigation's restarts as dashed lines.
  const innovationCharts = new Map();
  function drawInnovations() {
    if (destroyed) return;
    const e = store.estimators.get('stage3');
    const names = e ? [...e.innovations.keys()] : [];
    innovationsCard.hidden = names.length === 0;
    if (!names.length) return;
    const latest = e.latest || {};
    const note = `${latest.updates ?? 0} updates, ${latest.rejected ?? 0} innovations rejected; ` +
      `navigation restarted ${latest.restarts ?? 0} time(s)${e.restarts.length ? ` (at ${e.restarts.map((t) => duration(t)).join(', ')})` : ''}. ` +
      'An innovation outside its gate (5 σ) is rejected.';
    const noteEl = root.querySelector('#innovations-note');
    if (noteEl.textContent !== note) noteEl.textContent = note;
    const grid = root.querySelector('#innovations');
    for (const name of names) {
      let chart = innovationCharts.get(name);
      if (!chart) {
        const box = h('div', { class: 'conv-chart', dataset: { innovation: name } });
        grid.append(box);
        chart = lineChart(box, { title: `${name}  [${unitOf(name)}]`, x: 'program s', y: unitOf(name), height: 170, legend: false,
          series: [{ label: 'innovation', color: COLORS[0] }, { label: '−gate', band: true }, { label: '+gate', band: true }],
          bands: [[3, 2, 'rgba(46,125,50,0.12)']], markers: () => store.estimators.get('stage3')?.restarts || [] });
        innovationCharts.set(name, chart);
      }
      chart.setData(e.innovations.get(name).view(Infinity, 1500));
    }
  }

  function drawPlots() {
    if (destroyed) return;
    angles.setData(store.angles.view(windowS));
    rates.setData(store.rates.view(windowS));
    chamber.setData(store.chamber.view(windowS));
    frameRate.setData(store.frameRate.view(windowS));
  }

  const set = (id, text) => {
    const el = root.querySelector(`#${id}`);
    if (el && el.textContent !== text) el.textContent = text;
  };
  const flags = (id, list) => {
    const el = root.querySelector(`#${id}`);
    const sig = list.map((f) => f.join(':')).join('|');
    if (!el || el.dataset.sig === sig) return;
    el.dataset.sig = sig;
    clear(el).append(...list.map(([cls, text]) => h('span', { class: `flag ${cls}` }, text)));
  };

  // The last run's end: what it was, how it ended, where its results are; the plots and the
  // convergence below are still its own.
  function drawFinished(fin) {
    const sig = fin ? `${fin.id}|${fin.state}|${fin.name}` : '';
    if (finishedBox.dataset.sig === sig) return;
    finishedBox.dataset.sig = sig;
    finishedBox.hidden = !fin;
    if (!fin) { finishedBox.replaceChildren(); finishedBox.dataset.campaign = ''; return; }
    finishedBox.dataset.campaign = String(fin.id);
    finishedBox.replaceChildren(`The last run, campaign ${fin.id}${fin.name ? ` (${fin.name})` : ''}, has ended`,
      fin.state ? ': ' : '.', fin.state ? stateBadge(fin.state) : '', fin.state ? '. ' : ' ',
      h('a', { href: `#/campaigns/${fin.id}`, id: 'finished-run-link' }, `See the results of campaign ${fin.id}`),
      '. The plots and the convergence below are its own until another run starts.');
  }

  let lastSuspendReason = '';
  function drawPaused(run) {
    const paused = run && (run.state === 'paused' || run.state === 'pausing');
    pausedBanner.hidden = !paused;
    if (!paused) { pauseFor = ''; pauseTransitions = null; return; }
    if (pauseFor !== String(run.id)) {
      pauseFor = String(run.id);
      get(`/api/campaigns/${run.id}`).then((d) => {
        if (pauseFor === String(d.id)) { pauseTransitions = d.transitions || []; drawPaused(current); }
      }).catch(() => { /* the banner says "Paused." and how to go on without who */ });
    }
    const text = pauseNote(pauseTransitions, timeOfDay).text;
    if (pausedBanner.textContent !== text) pausedBanner.textContent = text;
  }
  function drawNumbers() {
    if (destroyed) return;
    const m = store.latest;
    const run = m?.run || null;
    current = run ? { id: run.id, name: run.name, state: run.state } : null;
    commands.update();
    if (run) {
      runTitle.textContent = `#${run.id} ${run.name}`;
      if (runState.dataset.state !== run.state) {
        runState.dataset.state = run.state;
        clear(runState).append(stateBadge(run.state));
      }
      const seg = run.segment || {};
      set('run-step', runStepText(run));
      set('run-time', `program ${duration(run.program_time_s)} of ${duration(run.duration_s)} · checkpoint ${duration(run.checkpoint_s)}`);
      const wallLeft = run.speed_factor > 0 ? run.time_left_s / run.speed_factor : null;
      set('run-left', `time left ${duration(run.time_left_s)}${wallLeft !== null && Math.abs(run.speed_factor - 1) > 0.05 ? ` (≈ ${duration(wallLeft)} wall)` : ''}`);
      set('run-speed', run.speed_factor ? `speed ×${num(run.speed_factor, 3)}` : '');
      const pct = run.duration_s > 0 ? Math.min(100, (100 * run.program_time_s) / run.duration_s) : 0;
      progress.firstChild.style.width = `${pct}%`;
      progress.lastChild.textContent = `${pct.toFixed(1)} %`;
      const asked = run.prompt || null;
      if (asked && (promptBox.hidden || promptBox.dataset.segment !== String(asked.segment))) {
        promptRun = run.id;
        promptBox.dataset.segment = String(asked.segment);
        promptText.textContent = `${asked.text} (asked at ${timeOfDay(asked.since)})`;
        promptDone.disabled = !isOperator();
        promptDone.title = isOperator() ? '' : 'operator role required (you are signed in as a viewer)';
        promptError.textContent = '';
      }
      promptBox.hidden = !asked;
      const suspended = run.state === 'suspended';
      suspendedBanner.hidden = !suspended;
      if (suspended) suspendedBanner.textContent = `Suspended${lastSuspendReason ? `: ${lastSuspendReason}` : ''}. The run resumes by itself once the condition has cleared and settled; the interrupted segment is then redone.`;
      drawPaused(run);
    } else {
      runTitle.textContent = 'Nothing runs';
      clear(runState);
      runState.dataset.state = '';
      set('run-step', 'The readings below are the idle bench.');
      set('run-time', '');
      set('run-left', '');
      set('run-speed', '');
      progress.firstChild.style.width = '0%';
      progress.lastChild.textContent = '';
      suspendedBanner.hidden = true;
      drawPaused(null);
      promptBox.hidden = true;
    }
    drawFinished(run ? null : store.finished);
    if (!m) return;
    const tb = m.table || {};
    AXES.forEach((a, i) => {
      set(`angle-${a}`, fixed(tb.angle_deg?.[i], 3));
      set(`rate-${a}`, fixed(tb.rate_dps?.[i], 3));
    });
    flags('table-flags', [
      tb.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      tb.homed ? ['ok', 'homed'] : ['warn', 'not homed'],
      tb.interlock_closed ? ['warn', 'interlock closed (may move)'] : ['ok', 'interlock open'],
      ...(tb.fault ? [['bad', `fault: ${tb.fault}`]] : []),
    ]);
    const ch = m.chamber || {};
    set('chamber-temp', fixed(ch.temperature_C, 2));
    set('chamber-sp', fixed(ch.setpoint_C, 2));
    set('chamber-tol', fixed(ch.tolerance_C, 2));
    flags('chamber-flags', [
      ch.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      ch.in_band === false ? ['bad', 'out of band'] : ['ok', 'in band'],
    ]);
    // A run's counters belong to the run: the idle bench shows none of the last run's figures.
    const imu = run ? (m.imu || {}) : { connected: m.imu?.connected };
    set('imu-rate', fixed(imu.frame_rate_hz, 1));
    set('imu-frames', String(imu.frames ?? '—'));
    set('imu-lost', String(imu.lost_frames ?? '—'));
    set('imu-bad', String(imu.bad_frames ?? '—'));
    const rec = run ? (m.recorder || {}) : {};
    set('rec-queue', `${rec.queue_frames ?? '—'} (peak ${rec.queue_high_water_frames ?? '—'})`);
    set('rec-committed', String(rec.committed_frames ?? '—'));
    flags('imu-flags', [
      imu.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      ...(imu.lost_frames > 0 ? [['warn', `${imu.lost_frames} lost`]] : []),
      ...(imu.bad_frames > 0 ? [['warn', `${imu.bad_frames} bad`]] : []),
      ...(rec.dropped_frames > 0 ? [['bad', `recorder dropped ${rec.dropped_frames}`]] : []),
      ...(store.droppedMessages > 0 ? [['warn', `${store.droppedMessages} live messages skipped (slow page)`]] : []),
    ]);
    const estBox = root.querySelector('#estimator-status');
    const est = run ? (m.estimators || {}) : {};
    const sig = JSON.stringify(Object.entries(est).map(([k, e]) => [k, e.status, e.statics, e.rotations, e.message, e.max_velocity_error_mps, e.max_position_error_m, e.filter_status, e.updates, Math.round(e.program_time_s || 0)]));
    if (estBox.dataset.sig !== sig) {
      estBox.dataset.sig = sig;
      clear(estBox);
      if (!Object.keys(est).length) estBox.append(h('p', { class: 'muted' }, run ? 'No estimator runs in this campaign.' : '—'));
      for (const [name, e] of Object.entries(est)) {
        // During a run, a stage that lacks data has not had its part of the program yet (or not
        // all of it): said neutrally, what it still needs folded away, not as a warning.
        const pending = e.status === 'undetermined' || e.status === 'waiting';
        const started = (e.statics ?? 0) > 0 || (e.updates ?? 0) > 0 || Object.keys(e.estimates || {}).length > 0;
        const label = pending ? (started ? 'not determined yet' : 'not reached yet') : e.status;
        estBox.append(h('div', { class: 'estimator', dataset: { estimator: name, status: e.status } },
          h('strong', {}, name), ' ', h('span', { class: `badge est-${pending ? 'pending' : e.status}` }, label),
          e.statics !== undefined ? h('div', { class: 'muted' }, `${e.statics} statics, ${e.rotations ?? 0} rotations, at ${duration(e.program_time_s)}`) : null,
          e.max_velocity_error_mps !== undefined ? h('div', { class: 'muted' }, `max velocity error ${num(e.max_velocity_error_mps, 3)} m/s, position ${num(e.max_position_error_m, 3)} m`) : null,
          e.filter_status !== undefined ? h('div', { class: `muted filter-status${e.filter_status === 'running' ? '' : ' warn'}`, dataset: { filterStatus: e.filter_status.split(':')[0] } },
            `filter ${e.filter_status}; ${e.updates ?? 0} updates, ${e.rejected ?? 0} rejected, ${e.restarts ?? 0} restart(s), at ${duration(e.program_time_s)}`) : null,
          // The whole message: a stage that cannot determine something lists what, one per line.
          e.message && pending ? h('details', { class: 'estimator-needs' }, h('summary', {}, 'what it still needs'), h('div', { class: 'muted pre-line' }, e.message))
            : e.message ? h('div', { class: 'estimator-message' }, e.message) : null));
      }
    }
  }

  function addEvent(e) {
    root.querySelector('#events-empty').hidden = true;
    const what = e.kind === 'transition' ? `${e.from} → ${e.to}` : e.kind;
    const serious = ['suspended', 'alarm', 'error', 'interrupted'].includes(e.kind) || ['failed', 'suspended', 'aborted'].includes(e.to);
    if (e.kind === 'suspended' || e.to === 'suspended') lastSuspendReason = e.reason || lastSuspendReason;
    eventsBody.prepend(h('tr', { class: serious ? 'event-serious' : '', dataset: { kind: e.kind } },
      h('td', {}, timeOfDay(e.t)), h('td', {}, e.campaign ?? ''), h('td', {}, what), h('td', {}, e.reason || '')));
    while (eventsBody.children.length > 200) eventsBody.lastChild.remove();
  }

  for (const e of store.events.items) addEvent(e);
  const onTelemetry = () => {
    schedule(drawNumbers);
    schedule(drawPlots);
    schedule(drawPick);
    schedule(drawInnovations);
    conv.update();
  };
  const onEvent = (ev) => addEvent(ev.detail);
  const onProgress = () => {
    schedule(drawPick);
    schedule(drawInnovations);
    conv.update();
  };
  store.addEventListener('telemetry', onTelemetry);
  store.addEventListener('event', onEvent);
  store.addEventListener('progress', onProgress);
  store.addEventListener('run', wholeRunMode);
  onTelemetry();
  wholeRunMode();

  return () => {
    destroyed = true;
    store.removeEventListener('telemetry', onTelemetry);
    store.removeEventListener('event', onEvent);
    store.removeEventListener('progress', onProgress);
    store.removeEventListener('run', wholeRunMode);
    clearInterval(recordingTimer);
    clearInterval(dueDatesTimer);
    recording?.();
    angles.destroy();
    rates.destroy();
    chamber.destroy();
    frameRate.destroy();
    conv.destroy();
    for (const c of innovationCharts.values()) c.destroy();
  };
}
