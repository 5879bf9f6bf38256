// One campaign: its state and commands while it runs, and its results when it is done: the
// coefficient table with sigmas (with the truth and the error in simulated runs), the estimators'
// convergence, the Allan, thermal and Schuler-test plots imucald computes from the recording (or
// what the run would need for them), the downloads
// (model JSON, recording bundle, printable certificate), and the record of what happened.
import { get, post, ApiError } from '../api.mjs';
import { verdictBadge } from '../components/verdict_badge.mjs';
import { h, clear, duration, dateTime, timeOfDay, num, stateBadge, outcomeBadge, FINAL_STATES } from '../format.mjs';
import { pauseNote } from '../outcome.mjs';
import { commandBar, confirmDialog } from '../dialogs.mjs';
import { isOperator } from '../session.mjs';
import { coefficientRows, unitOf, groupOf, labelOf } from '../coefficients.mjs';
import { convergencePanel } from '../convergence.mjs';
import { contributionRows } from '../contributions.mjs';
import { Series } from '../series.mjs';
import { lineChart, COLORS } from '../plots.mjs';
import { alarmTable } from '../alarm_panel.mjs';
import { recordingPlots } from '../recording_plots.mjs';

// The recording bundle's link (GET .../recording, a tar): written from the run file once the run
// has ended, by a job on imucald (202 with its progress until the file is there). A click asks
// until then, showing how far it is, and then lets the browser download the file itself.
function recordingLink(link, id, detail, { isStopped, onError }) {
  const url = `/api/campaigns/${id}/recording`;
  if (!detail.run_db || !FINAL_STATES.has(detail.state)) {
    link.title = detail.run_db ? 'Available when the run has ended.' : 'This campaign was never started: there is no recording.';
    link.classList.add('disabled');
    return;
  }
  link.href = url;
  link.setAttribute('download', `campaign-${id}-recording.tar`);
  link.removeAttribute('aria-disabled');
  link.title = 'imucal-recording/1 bundle (meta.json, frames.csv, program.json, truth.json) as one tar file; unpack and read it with "imucal import DIR"';
  link.addEventListener('click', (event) => {
    if (link.dataset.ready === 'true') return;  // the click below: the browser downloads
    event.preventDefault();
    if (link.dataset.preparing !== 'true') prepareRecording(link, url, { isStopped, onError });
  });
}

async function prepareRecording(link, url, { isStopped, onError }) {
  const label = link.textContent;
  link.dataset.preparing = 'true';
  try {
    await get(url, { discardBody: true, onPending: (p) => {
      if (isStopped()) return false;
      link.dataset.progress = String(p?.progress ?? 0);
      link.textContent = p?.state === 'queued' ? 'Recording bundle: queued behind other jobs…'
        : `Recording bundle: writing… ${Math.round(100 * (p?.progress ?? 0))} %`;
      return true;
    } });
    if (isStopped()) return;
    link.textContent = label;
    link.dataset.ready = 'true';
    link.click();
  } catch (e) {
    if (isStopped()) return;
    link.textContent = label;
    onError(`The recording bundle could not be written: ${e.message}`);
  } finally {
    delete link.dataset.preparing;
    delete link.dataset.ready;
  }
}

export function mount(root, ctx) {
  const id = ctx.params.id;
  let detail = null;
  let modelNoise = null;  // the run's model, for the Allan panel's comparison
  let stopped = false;
  let timer = null;
  let resultsFor = null;  // the state for which the results were loaded
  const cleanups = [];

  const title = h('h1', { id: 'campaign-title' }, `Campaign ${id}`);
  const badge = h('span', { id: 'campaign-state' });
  const pageError = h('div', { class: 'form-error', role: 'alert', id: 'campaign-error' });
  const commands = commandBar({
    getCampaign: () => detail && { id: detail.id, name: detail.name, state: detail.state },
    onDone: () => refresh(),
  });
  const meta = h('dl', { class: 'meta', id: 'campaign-meta' });
  const liveStrip = h('div', { class: 'live-strip', id: 'campaign-live', hidden: true });
  const pausedBanner = h('div', { class: 'suspended-banner paused-banner', id: 'paused-banner', role: 'status', hidden: true });
  const results = h('section', { class: 'card', id: 'results', hidden: true });
  const record = h('section', { class: 'card', id: 'record' });
  root.append(
    h('div', { class: 'page-head' }, h('div', { class: 'title-line' }, title, badge), commands),
    pageError,
    h('section', { class: 'card' }, meta, pausedBanner, liveStrip),
    results, record);

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
        loadResults();
      } else if (!final && !resultsFor && Object.keys(d.results || {}).length) {
        resultsFor = 'partial';
        loadResults();
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
    renderRecord();
  }

  // ---- the live strip while this campaign is the active run ----

  const onTelemetry = (ev) => {
    const run = ev.detail.run;
    const mine = run && run.id === id;
    liveStrip.hidden = !mine;
    if (!mine) return;
    const seg = run.segment || {};
    const text = `Live: ${run.state}, step ${seg.index + 1}/${seg.count} ${seg.name}, program ${duration(run.program_time_s)} of ${duration(run.duration_s)}, ${duration(run.time_left_s)} left`;
    if (liveStrip.firstChild?.textContent !== text) {
      clear(liveStrip).append(h('span', {}, text), ' ', h('a', { href: '#/live' }, 'open the live view'));
    }
    if (detail && run.state !== detail.state) {
      detail.state = run.state;
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

  // ---- results ----

  // The certificate of a run that counts as a calibration; for a partial run, its acceptance first
  // (an operator's, with a reason: it is kept with the run and in the audit trail).
  function certificateControl(d) {
    const link = h('a', { class: 'button', id: 'certificate', href: `certificate.html?id=${id}`, target: '_blank', rel: 'noopener' }, 'Calibration certificate (print)');
    if (d.complete || d.accepted) return link;
    const note = h('span', { class: 'muted', id: 'not-accepted' }, 'Partial run, not accepted: no certificate is issued until an operator accepts it.');
    if (!isOperator()) return note;
    const accept = h('button', { type: 'button', id: 'accept-partial' }, 'Accept as calibration…');
    accept.addEventListener('click', async () => {
      const answer = await confirmDialog({
        title: `Accept campaign ${id} as its unit's calibration?`,
        body: [`It ended ${d.state} at ${Math.round(100 * (d.progress || 0))} % of its program. Accepted, it counts as a calibration and its certificate is issued, stating the partial run and your reason.`],
        confirmLabel: 'Accept', reason: true,
      });
      if (!answer.ok) return;
      if (!answer.reason) {
        pageError.textContent = 'Not accepted: say why the partial run is good enough (the reason is kept with the run).';
        return;
      }
      try {
        await post(`/api/campaigns/${id}/accept`, { reason: answer.reason });
        resultsFor = null;
        await refresh();
      } catch (e) {
        pageError.textContent = `Not accepted: ${e.message}`;
      }
    });
    return h('span', {}, note, ' ', accept);
  }

  async function loadResults() {
    const d = detail;
    results.hidden = false;
    clear(results).append(h('h2', {}, 'Results'));
    // The truth of a simulated run in the model's frame (imucald turns it, written in the
    // instrument frame, into a body-frame model's frame): asked only when the run has both.
    const hasTruth = d.spec && typeof d.spec.truth === 'object' && d.spec.truth !== null;
    const [model, progress, status, comparison] = await Promise.all([
      d.has_model ? get(`/api/campaigns/${id}/model`).catch((e) => ({ _error: e })) : null,
      get(`/api/campaigns/${id}/progress`).catch(() => null),
      ctx.status().catch(() => null),
      d.has_model && hasTruth ? get(`/api/campaigns/${id}/truth`).catch(() => null) : null,
    ]);
    if (stopped) return;
    modelNoise = model && !model._error ? model : null;
    const truth = comparison && Array.isArray(comparison.rows) ? comparison : null;
    const simulated = (status?.devices || '').startsWith('sim') || hasTruth;

    // Downloads
    const downloads = h('div', { class: 'downloads', id: 'downloads' });
    if (d.has_model) {
      downloads.append(
        h('a', { class: 'button primary', id: 'download-model', href: `/api/campaigns/${id}/model`, download: `campaign-${id}-model-instrument.json` }, 'Model JSON (instrument frame)'),
        h('a', { class: 'button', id: 'download-model-body', href: `/api/campaigns/${id}/model?frame=body`, download: `campaign-${id}-model-body.json` }, 'Model JSON (body frame)'),
        certificateControl(d));
    } else {
      downloads.append(h('span', { class: 'muted', id: 'no-model' }, d.state === 'done' ? 'This campaign produced no model (see the estimator notes below).' : `No model: the campaign ended ${d.state}.`));
    }
    const bundle = h('a', { class: 'button', id: 'download-recording', 'aria-disabled': 'true' }, 'Recording bundle (tar)');
    if (Object.keys(d.results || {}).length)
      downloads.append(h('a', { class: 'button', id: 'test-report', href: `report.html?id=${id}`, target: '_blank', rel: 'noopener' }, 'Test report (print)'));
    downloads.append(bundle, h('button', { type: 'button', class: 'link', id: 'download-record', onclick: () => saveJson(`campaign-${id}.json`, detail) }, 'Campaign record (JSON)'));
    results.append(downloads);
    recordingLink(bundle, id, d, { isStopped: () => stopped, onError: (text) => { pageError.textContent = text; } });

    // Coefficients
    if (model && !model._error) {
      results.append(coefficientTable(model, truth, simulated));
      results.append(verdictSection(d));
    } else if (model?._error) {
      results.append(h('p', { class: 'form-error' }, `Cannot load the model: ${model._error.message}`));
    }

    // What each calibration stage contributed (a campaign of several stages, e.g. `full`).
    const stageNames = ['direct', 'lever-arm', 'stage3'].filter((n) => d.results?.[n]?.status === 'done' && d.results[n].model);
    if (stageNames.length >= 2) {
      const models = await Promise.all(stageNames.map((n) => get(`/api/campaigns/${id}/model?stage=${n}&frame=body`).catch(() => null)));
      if (stopped) return;
      if (models.every(Boolean)) {
        const stages = stageNames.map((stage, k) => ({ stage, model: models[k] }));
        results.append(contributionsTable(stages, d.results.stage3?.uncertainty_reduction || null));
      }
    }
    const delays = d.results?.stage3?.relative_gyro_delays_us;
    if (delays) {
      results.append(h('p', { id: 'relative-delays' }, 'Relative gyro delays (stage 3): ',
        `τ_yx = ${num(delays.tau_yx, 3)} ± ${num(delays.sigma_tau_yx, 2)} µs, τ_zx = ${num(delays.tau_zx, 3)} ± ${num(delays.sigma_tau_zx, 2)} µs `,
        h('span', { class: 'muted' }, '(gyro y and z against gyro x: what coning sees; their sigma is smaller than each delay\'s own).')));
    }

    // The rate-steps test: scale factor against rate, per gyro (IEEE 952).
    const rateSteps = d.results?.['rate-steps']?.rate_steps;
    if (rateSteps?.axes?.length) results.append(rateStepsSection(rateSteps));
    const tumble = d.results?.tumble?.tumble;
    if (tumble?.positions?.length) results.append(tumbleSection(tumble));
    const warmUp = d.results?.['warm-up']?.warm_up;
    if (warmUp?.channels?.length) results.append(warmUpSection(warmUp));
    const repeat = d.results?.repeatability?.repeatability;
    if (repeat?.channels?.length) results.append(repeatabilitySection(repeat));

    // What the estimators said
    const notes = h('div', { class: 'stage-results', id: 'stage-results' });
    for (const [name, r] of Object.entries(d.results || {})) {
      const facts = Object.entries(r).filter(([k, v]) => k !== 'message' && (typeof v === 'number' || typeof v === 'string'));
      notes.append(h('div', { class: 'stage', dataset: { estimator: name } }, h('h3', {}, `${name}`),
        // Counts as integers ("22 statics"), quantities with their unit, names without it.
        h('dl', { class: 'meta compact' }, ...facts.flatMap(([k, v]) => [h('dt', {}, labelOf(k)),
          h('dd', {}, typeof v === 'number' ? (Number.isInteger(v) ? String(v) : `${num(v)} ${unitOf(k)}`.trim()) : v)])),
        // The whole message, one line each: a stage that cannot determine something lists what.
        typeof r.message === 'string' ? h('div', { class: 'estimator-message' }, r.message) : null,
        Array.isArray(r.notes) && r.notes.length ? h('ul', { class: 'notes' }, ...r.notes.map((n) => h('li', {}, n))) : null));
    }
    if (notes.childElementCount) results.append(h('h3', {}, 'Estimators'), notes);

    // Convergence over the run
    // Only stages whose progress carries estimates (the warm-up and repeatability report counts).
    const converging = Object.keys(progress || {}).filter((n) => (progress[n] || []).some((p) => Object.keys(p.estimates || {}).length));
    if (converging.length) {
      // Stage 3's convergence when it ran (the final refinement), else stage 1's, else the first.
      const name = converging.includes('stage3') ? 'stage3' : converging.includes('direct') ? 'direct' : converging[0];
      const restarts = (progress[name] || []).reduce((r, p) => (Array.isArray(p.restart_times_s) ? p.restart_times_s : r), []);
      const map = new Map();
      for (const p of progress[name] || []) {
        for (const [coef, pair] of Object.entries(p.estimates || {})) {
          if (!Array.isArray(pair)) continue;
          if (!map.has(coef)) map.set(coef, new Series(3, { recentCapacity: 4000, historyCapacity: 2000 }));
          const [v, s] = pair;
          map.get(coef).push(p.program_time_s, [v, v - s, v + s]);
        }
      }
      if (map.size) {
        const box = h('div', { id: 'results-convergence' });
        results.append(h('h3', {}, `Convergence of the ${name} estimator (estimate ± σ over program time)`), box);
        const panel = convergencePanel(box, () => map, { idPrefix: 'res-conv', markers: () => restarts });
        panel.update();
        cleanups.push(() => panel.destroy());
      }
    }

    // The run itself, from its recording: table, rates and temperatures, zoomable.
    if (d.run_db) {
      const box = h('div', { class: 'recording-plots', id: 'recording-plots' });
      results.append(h('h3', {}, 'The run: table, IMU and temperatures from the recording'), box);
      cleanups.push(recordingPlots(box, id));
    }

    // Plots whose data the API may provide (docs/web.md lists what it lacks today).
    const optional = h('div', { class: 'optional-plots', id: 'optional-plots' });
    results.append(h('h3', {}, 'Noise, thermal and navigation evaluation'), optional);
    await optionalPlots(optional);
  }

  // Each panel asks imucald for its data; a run that cannot give it gets the daemon's reason
  // ({"available": false, "reason": "not available for this run: needs program ..."}, a 200, so
  // that the browser logs no error), shown in the panel.
  async function optionalPlots(box) {
    const sources = [
      { key: 'allan', title: 'Allan deviation', render: renderAllan },
      { key: 'thermal', title: 'Coefficients against temperature, before and after compensation', render: renderThermal },
      { key: 'evaluation', title: 'Schuler test: navigation errors of the model variants', render: renderEvaluation },
    ];
    await Promise.all(sources.map(async (s) => {
      const el = h('div', { class: 'optional-plot', id: `plot-${s.key}` }, h('h4', {}, s.title));
      const note = h('p', { class: 'muted', id: `plot-${s.key}-status` }, 'Computing from the recording…');
      el.append(note);
      box.append(el);
      // A campaign never started has no recording: nothing to ask imucald for.
      if (!detail.run_db) {
        el.dataset.available = 'false';
        note.className = 'muted not-available';
        note.textContent = 'Not available: the campaign was never started (no recording).';
        return;
      }
      try {
        // Computed as a job on imucald (202 until ready): say how far it is meanwhile.
        const data = await get(`/api/campaigns/${id}/${s.key}`, { onPending: (p) => {
          if (stopped) return false;
          note.textContent = p?.state === 'queued' ? `Queued behind ${Math.max(0, (p.queue_position ?? 1) - 1)} other computation(s)…`
            : `Computing from the recording… ${Math.round(100 * (p?.progress ?? 0))} %`;
          note.dataset.progress = String(p?.progress ?? 0);
          return true;
        } });
        if (stopped) return;
        // What the run cannot give is an answer, not an error (docs/api.md): {available: false, reason}.
        if (data && data.available === false) {
          el.dataset.available = 'false';
          note.className = 'muted not-available';
          const reason = String(data.reason || 'not available for this run');
          note.textContent = `${reason[0].toUpperCase()}${reason.slice(1)}.`;
          return;
        }
        note.remove();
        el.dataset.available = 'true';
        s.render(el, data);
      } catch (e) {
        el.dataset.available = 'false';
        note.className = e instanceof ApiError && (e.status === 404 || e.status === 409) ? 'muted not-available' : 'form-error';
        note.textContent = e instanceof ApiError && e.status === 404 && /^not available/.test(e.message)
          ? `${e.message[0].toUpperCase()}${e.message.slice(1)}.` : `${s.title}: ${e.message}`;
      }
    }));
    // Keep the panels in their order whatever answered first.
    for (const s of sources) box.append(box.querySelector(`#plot-${s.key}`));
  }

  function renderAllan(el, data) {
    // {gyro_x: {tau_s, adev, unit}, ..., accel_z: {...}, arw_deg_rth, vrw_mps_rth, notes}
    const row = h('div', { class: 'plot-row' });
    el.append(row);
    for (const [sensor, label] of [['gyro', 'Gyros'], ['accel', 'Accelerometers']]) {
      const axes = ['x', 'y', 'z'].map((a) => data[`${sensor}_${a}`]).filter(Boolean);
      if (!axes.length) continue;
      const tau = axes[0].tau_s;
      const box = h('div', { class: 'plot' });
      row.append(box);
      const c = lineChart(box, { title: `${label}: Allan deviation`, x: 'τ s', y: axes[0].unit, log: true, height: 220,
        series: ['x', 'y', 'z'].map((a, i) => ({ label: a, color: COLORS[i] })), points: true });
      c.setData([tau, ...axes.map((a) => tau.map((_, i) => a.adev[i] ?? null))]);
      cleanups.push(() => c.destroy());
    }
    const fmt3 = (v) => (v || []).map((x) => (x == null ? '—' : num(x, 3))).join(', ');
    el.append(h('p', { class: 'muted' },
      `Angle random walk ${fmt3(data.arw_deg_rth)} °/√h; velocity random walk ${fmt3(data.vrw_mps_rth)} m/s/√h (x, y, z)`,
      data.bias_instability_dph?.some((v) => v != null) ? `; bias instability ${fmt3(data.bias_instability_dph)} °/h` : '',
      `. ${(data.notes || []).join(' ')}`));
    // The model's noise terms beside them, and why the two differ (docs/calibration.md).
    const arw = modelNoise?.gyro?.noise?.arw_deg_rth, vrw = modelNoise?.accel?.noise?.vrw_mps_rth;
    if (typeof arw === 'number' || typeof vrw === 'number') {
      el.append(h('p', { class: 'muted', id: 'allan-vs-model' },
        `The model's noise terms: angle random walk ${num(arw, 3)} °/√h, velocity random walk ${num(vrw, 3)} m/s/√h. `,
        'They are the per-sample scatter of the statics (every noise at the sample rate, quantisation included: what the ',
        'stage-3 filter needs per step); the Allan figures are the τ^-½ coefficient for τ ≤ 1 s. They agree when white noise ',
        'dominates at the sample rate; where quantisation dominates (an error-free simulated IMU) the Allan figures are smaller.'));
    }
  }

  function renderThermal(el, data) {
    // {T_ref_C, cycles_used, coefficients: {name: {T_C: [...], before: [...], after: [...], truth: [...]}}}
    el.append(h('p', { class: 'muted' }, `${data.cycles_used} of ${data.cycles_total} table cycles used, reference ${num(data.T_ref_C, 3)} °C, `,
      `input: ${data.input_model || 'the campaign\'s model'}. Points: the per-cycle estimate (before) and the estimate less the fitted thermal model (after).`));
    const row = h('div', { class: 'plot-row wrap' });
    el.append(row);
    for (const [name, v] of Object.entries(data.coefficients || {})) {
      // Heating and cooling pass the same temperatures: points sorted by T, no lines.
      const order = v.T_C.map((_, i) => i).sort((a, b) => v.T_C[a] - v.T_C[b]);
      const pick = (list) => order.map((i) => list?.[i] ?? null);
      const withTruth = (v.truth || []).some((x) => x != null);
      const box = h('div', { class: 'plot third' });
      row.append(box);
      const c = lineChart(box, { title: `${name} [${unitOf(name)}]`, x: 'T °C', height: 170, points: true,
        series: [{ label: 'before', color: COLORS[1], width: 0 }, { label: 'after', color: COLORS[2], width: 0 },
          ...(withTruth ? [{ label: 'truth', color: COLORS[0], width: 1, dash: [4, 4] }] : [])] });
      c.setData([pick(v.T_C), pick(v.before), pick(v.after), ...(withTruth ? [pick(v.truth)] : [])]);
      cleanups.push(() => c.destroy());
    }
  }

  function renderEvaluation(el, data) {
    // {variants: [{name, source, tilt_schuler_amplitude_mps, ..., segments: [{name, kind, time_s, velocity_error_mps}]}]}
    const variants = data.variants || [];
    el.append(h('table', { class: 'list compact', id: 'evaluation-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'variant'), h('th', {}, 'model'), h('th', { class: 'num' }, 'tilt Schuler amplitude m/s'),
        h('th', { class: 'num' }, 'coning Schuler amplitude m/s'), h('th', { class: 'num' }, 'implied accel error m/s²'), h('th', { class: 'num' }, 'implied gyro drift °/h'))),
      h('tbody', {}, ...variants.map((v) => h('tr', { dataset: { variant: v.name } }, h('td', {}, v.name), h('td', {}, v.source),
        h('td', { class: 'num' }, num(v.tilt_schuler_amplitude_mps, 3)), h('td', { class: 'num' }, num(v.coning_schuler_amplitude_mps, 3)),
        h('td', { class: 'num' }, num(v.implied_accel_error_mps2, 3)), h('td', { class: 'num' }, num(v.implied_gyro_drift_dph, 3)))))));
    const row = h('div', { class: 'plot-row wrap' });
    el.append(row);
    const segments = variants[0]?.segments || [];
    segments.forEach((seg, k) => {
      const t0 = seg.time_s[0] ?? 0;
      const box = h('div', { class: 'plot third' });
      row.append(box);
      const c = lineChart(box, { title: `${seg.name} (${seg.kind}): horizontal velocity error`, x: 's from start', y: 'm/s', height: 190,
        series: variants.map((v, i) => ({ label: v.name, color: COLORS[i % COLORS.length] })) });
      c.setData([seg.time_s.map((t) => t - t0), ...variants.map((v) => seg.time_s.map((_, i) => v.segments[k]?.velocity_error_mps[i] ?? null))]);
      cleanups.push(() => c.destroy());
    });
  }

  // The verdict against the unit's part number's limits (GET /api/campaigns/{id}: verdict).
  function verdictSection(d) {
    const v = d.verdict;
    if (!v) {
      return h('p', { class: 'muted', id: 'acceptance-verdict' }, d.imu?.part_number
        ? `No acceptance limits for part number ${d.imu.part_number} (Units → Acceptance limits).`
        : 'The campaign names no part number: no acceptance limits apply.');
    }
    const limit = (x) => (x == null ? '—' : num(x, 3));
    return h('div', { id: 'acceptance-verdict' },
      h('h3', {}, 'Acceptance ', verdictBadge(v.pass), ` part number ${v.part_number}`),
      h('p', { class: 'muted' }, `${v.failures} of ${v.coefficients.length} limited coefficient${v.coefficients.length === 1 ? '' : 's'} fail; limits from ${v.limits}.`),
      h('table', { class: 'list', id: 'verdict-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, 'Value'), h('th', { class: 'num' }, 'σ'),
          h('th', { class: 'num' }, 'Limit |value|'), h('th', { class: 'num' }, 'Limit σ'), h('th', {}, ''), h('th', {}, 'Why'))),
        h('tbody', {}, ...v.coefficients.map((c) => h('tr', { class: c.pass ? '' : 'result-bad', dataset: { key: c.key } },
          h('td', {}, c.key), h('td', { class: 'num' }, num(c.value, 5)), h('td', { class: 'num' }, c.sigma == null ? '—' : num(c.sigma, 2)),
          h('td', { class: 'num' }, limit(c.limit_value)), h('td', { class: 'num' }, limit(c.limit_sigma)),
          h('td', {}, verdictBadge(c.pass)), h('td', {}, c.reason))))));
  }

  function coefficientTable(model, truth, simulated) {
    const all = coefficientRows(model, truth);
    const rows = all.filter((r) => r.estimated || groupOf(r.name));
    const skipped = [...new Set(all.filter((r) => !rows.includes(r)).map((r) => r.name.replace(/\.[xyz]$/, '')))];
    const withTruth = truth !== null;
    // Gyros on the left, accelerometers and the rest on the right: the whole model on one screen.
    const left = rows.filter((r) => r.name.startsWith('gyro.') && !r.name.includes('.noise.') && r.group !== 'Other');
    const right = rows.filter((r) => !left.includes(r));
    const bads = rows.filter((r) => r.ratio !== null && Math.abs(r.ratio) > 3).length;
    const frame = model.frame || 'instrument';
    const zeros = rows.filter((r) => r.byDefinition).map((r) => r.name);
    return h('div', { class: 'coefficients' },
      h('h3', {}, `Coefficients (${frame} frame)`),
      withTruth ? h('p', { class: bads ? 'result-bad' : 'result-ok', id: 'truth-verdict', dataset: { frame: truth.frame, truthFrame: truth.truth_frame } },
        bads ? `${bads} coefficient(s) are more than 3 σ from the simulation's truth (marked).` : 'Every coefficient is within 3 σ of the simulation\'s truth.',
        truth.converted ? ` The truth, written in the ${truth.truth_frame} frame, is compared in the ${truth.frame} frame.` : '',
        zeros.length ? ` ${zeros.join(', ')}: 0 by definition of the ${frame} frame (not judged).` : '')
        : (simulated ? h('p', { class: 'muted' }, 'The truth of this simulated run could not be read; the error is not shown.') : null),
      h('div', { class: 'coefficient-columns', id: 'coefficient-table' }, table(left, withTruth, frame), table(right, withTruth, frame)),
      skipped.length ? h('p', { class: 'muted' }, `Not estimated by this campaign (zero with zero σ in the model): ${skipped.join(', ')}.`) : null);
  }

  // Each stage's contribution, in the body frame: the first stage's value, what each later stage
  // changed, the final value and σ, and the filter's sqrt(P0/Pk) for stage 3's states.
  function contributionsTable(stages, reduction) {
    const rows = contributionRows(stages, reduction);
    const body = h('tbody');
    let group = null;
    for (const r of rows) {
      if (r.group !== group) {
        group = r.group;
        body.append(h('tr', { class: 'group-row' }, h('th', { colspan: stages.length + 4 }, group)));
      }
      body.append(h('tr', { dataset: { coefficient: r.name } },
        h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
        h('td', { class: 'unit' }, r.unit),
        ...r.changes.map((c, k) => h('td', { class: 'num' }, c === null ? '—' : (k > 0 && c > 0 ? '+' : '') + num(c, 4))),
        h('td', { class: 'num final' }, num(r.final, 5)),
        h('td', { class: 'num sigma' }, r.sigma === null ? '—' : num(r.sigma, 2)),
        h('td', { class: 'num reduction', title: 'sqrt(P0/Pk): how much stage 3 shrank this state\'s uncertainty' }, r.reduction === null ? '—' : num(r.reduction, 3))));
    }
    return h('div', { class: 'contributions', id: 'contributions' },
      h('h3', {}, 'What each stage contributed (body frame)'),
      h('p', { class: 'muted' }, `The value after ${stages[0].stage}, the change each later stage made, the final value and its σ; ` +
        'sqrt(P0/Pk): the factor by which stage 3 reduced the state\'s uncertainty (large: the program observes it well).'),
      h('table', { class: 'list compact contribution-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'coefficient'), h('th', {}, 'unit'),
          ...stages.map((s, k) => h('th', { class: 'num' }, k === 0 ? s.stage : `Δ ${s.stage}`)),
          h('th', { class: 'num' }, 'final'), h('th', { class: 'num' }, 'σ'), h('th', { class: 'num' }, '√(P0/Pk)'))),
        body));
  }

  function table(rows, withTruth, frame) {
    const body = h('tbody');
    let group = null;
    for (const r of rows) {
      if (r.group !== group) {
        group = r.group;
        body.append(h('tr', { class: 'group-row' }, h('th', { colspan: withTruth ? 7 : 4 }, group)));
      }
      const bad = r.ratio !== null && Math.abs(r.ratio) > 3;
      const data = { coefficient: r.name };
      if (r.ratio !== null) data.ratio = String(r.ratio);
      if (r.byDefinition) {
        data.byDefinition = 'true';
        body.append(h('tr', { dataset: data, class: 'by-definition' },
          h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
          h('td', { class: 'unit' }, r.unit),
          h('td', { class: 'num estimate', colspan: withTruth ? 5 : 2 }, `0 by definition of the ${frame} frame`)));
        continue;
      }
      body.append(h('tr', { dataset: data, class: bad ? 'out-3sigma' : '' },
        h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
        h('td', { class: 'unit' }, r.unit),
        h('td', { class: 'num estimate' }, num(r.estimate, 5)),
        h('td', { class: 'num sigma' }, r.sigma === null ? '—' : num(r.sigma, 2)),
        withTruth ? h('td', { class: 'num truth' }, r.truth === null ? '—' : num(r.truth, 5)) : null,
        withTruth ? h('td', { class: 'num error' }, r.error === null ? '—' : num(r.error, 3)) : null,
        withTruth ? h('td', { class: 'num ratio', title: 'error in sigmas; beyond ±3 is marked' }, r.ratio === null ? '—' : r.ratio.toFixed(2)) : null));
    }
    return h('table', { class: 'list compact coefficient-table' },
        h('thead', {}, h('tr', {}, h('th', {}, 'coefficient'), h('th', {}, 'unit'), h('th', { class: 'num' }, 'estimate'), h('th', { class: 'num' }, 'σ'),
          withTruth ? [h('th', { class: 'num' }, 'truth'), h('th', { class: 'num' }, 'error'), h('th', { class: 'num' }, 'error / σ')] : null)),
        body);
  }

  // The rate-steps stage's figures (docs/api.md, results.rate-steps.rate_steps): a table of the
  // IEEE 952 figures per gyro and, per gyro, each step's scale error at its rate with the fitted
  // model through them.
  function rateStepsSection(rs) {
    const pm = (pair, digits = 3) => (Array.isArray(pair) ? `${num(pair[0], 5)} ± ${num(pair[1], 2)}` : '—');
    const terms = (a) => (a.scale_nonlinear_ppm.length
      ? a.scale_nonlinear_ppm.map((c, k) => `c${k + 1} ${pm(c)}`).join(', ') : 'none (linear)');
    const tableEl = h('table', { class: 'list compact', id: 'rate-steps-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'gyro'), h('th', { class: 'num' }, 'scale + ppm'), h('th', { class: 'num' }, 'scale − ppm'),
        h('th', { class: 'num' }, 'asymmetry ppm'), h('th', { class: 'num' }, 'nonlinearity ppm of full scale'),
        h('th', {}, 'nonlinear terms ppm (q = |ω| / 100 °/s)'), h('th', { class: 'num' }, 'steps'))),
      h('tbody', {}, ...rs.axes.map((a) => h('tr', { dataset: { axis: a.axis } }, h('td', {}, a.axis),
        h('td', { class: 'num' }, pm(a.scale_pos_ppm)), h('td', { class: 'num' }, pm(a.scale_neg_ppm)),
        h('td', { class: 'num' }, pm(a.asymmetry_ppm)),
        h('td', { class: 'num' }, `${pm(a.nonlinearity_ppm_fs)} (at ${num(a.nonlinearity_at_dps, 3)} °/s of ${num(a.full_scale_dps, 3)})`),
        h('td', {}, terms(a)), h('td', { class: 'num' }, String(a.steps.length))))));
    const row = h('div', { class: 'plot-row wrap' });
    for (const a of rs.axes) {
      const box = h('div', { class: 'plot third', dataset: { axis: a.axis } });
      row.append(box);
      const c = lineChart(box, { title: `Gyro ${a.axis}: scale error against rate`, x: 'rate °/s', y: 'ppm', height: 220, points: true,
        series: [{ label: 'step', color: COLORS[1], width: 0 }, { label: 'step − σ', band: true }, { label: 'step + σ', band: true },
          { label: `model (degree ${a.degree})`, color: COLORS[0], width: 1.5 }],
        bands: [[3, 2, 'rgba(198, 40, 40, 0.15)']] });
      const steps = a.steps;
      c.setData([steps.map((st) => st.rate_dps), steps.map((st) => st.scale_ppm[0]),
        steps.map((st) => st.scale_ppm[0] - st.scale_ppm[1]), steps.map((st) => st.scale_ppm[0] + st.scale_ppm[1]),
        steps.map((st) => st.model_ppm[0])]);
      cleanups.push(() => c.destroy());
    }
    return h('div', { id: 'rate-steps' }, h('h3', {}, 'Scale factor against rate (rate-steps test, IEEE 952)'),
      h('p', { class: 'muted' }, 'Each step: the scale error at its cruise rate, ± σ (shaded). The model: the scale factors at zero rate ',
        'and the nonlinear terms, with the degree chosen by how well it predicts each rate left out. The nonlinearity is the largest ',
        'deviation of the output from its least-squares line over both signs (so an asymmetry shows in it too).'),
      tableEl, row);
  }

  // The tumble's residuals (docs/api.md, results.tumble.tumble): what every static left after the
  // fit, per accelerometer and per gyro, in the order of the positions (two whole turns).
  function tumbleSection(t) {
    const row = h('div', { class: 'plot-row' });
    const index = t.positions.map((_, i) => i + 1);
    for (const [key, title, unit, rms] of [['accel_residual_ug', 'Accelerometer residuals', 'µg', t.accel_residual_rms_ug],
      ['gyro_residual_dph', 'Gyro residuals', '°/h', t.gyro_residual_rms_dph]]) {
      const box = h('div', { class: 'plot', dataset: { kind: key } });
      row.append(box);
      const c = lineChart(box, { title: `${title} (rms ${rms.map((v) => num(v, 2)).join(', ')} ${unit})`, x: 'position', y: unit,
        height: 200, points: true, series: ['x', 'y', 'z'].map((a, i) => ({ label: a, color: COLORS[i], width: 1 })) });
      c.setData([index, ...[0, 1, 2].map((j) => t.positions.map((p) => p[key][j]))]);
      cleanups.push(() => c.destroy());
    }
    return h('div', { id: 'tumble' }, h('h3', {}, 'Tumble: what every position left after the fit (IEEE 1293)'),
      h('p', { class: 'muted' }, `${t.positions.length} statics: bias, scale, K2, K3 and angles per accelerometer, bias and `,
        'g-sensitivity per gyro (in the coefficient table). Residuals that follow the position (a pattern, not noise) mean a term the model lacks.'),
      row);
  }

  // The warm-up (IEEE 952): each channel's output from power-on less its settled value, with the
  // fitted transient; the figures per channel with their sigma.
  function warmUpSection(w) {
    const pm = ([v, s], digits) => `${num(v, digits)} ± ${num(s, 2)}`;
    const table = h('table', { class: 'list compact', id: 'warm-up-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'channel'), h('th', { class: 'num' }, 'transient at power-on'), h('th', { class: 'num' }, 'time constant'),
        h('th', { class: 'num' }, 'settled within the band after'), h('th', { class: 'num' }, 'band'))),
      h('tbody', {}, ...w.channels.map((c) => {
        const unit = c.unit === 'dph' ? '°/h' : 'µg';
        return h('tr', { dataset: { channel: `${c.sensor}.${c.axis}`, detected: String(c.detected) } },
          h('td', {}, `${c.sensor === 'gyro' ? 'gyro' : 'accelerometer'} ${c.axis}`),
          c.detected
            ? h('td', { class: 'num' }, `${pm(c.amplitude, 3)} ${unit}`)
            : h('td', { class: 'num muted' }, 'no transient above the noise'),
          h('td', { class: 'num' }, c.detected ? `${duration(c.time_constant_s[0])} ± ${duration(c.time_constant_s[1])}${c.resolved ? '' : ' (longer than the run)'}` : '—'),
          h('td', { class: 'num' }, c.detected ? `${duration(c.settle_time_s[0])} ± ${duration(c.settle_time_s[1])}` : '—'),
          h('td', { class: 'num' }, `± ${num(c.band, 2)} ${unit}`));
      })));
    const row = h('div', { class: 'plot-row' });
    const t_min = w.t_s.map((t) => t / 60);
    for (const [sensor, title, unit] of [['gyro', 'Gyro output from power-on, less its settled value', '°/h'], ['accel', 'Accelerometer output from power-on, less its settled value', 'µg']]) {
      const box = h('div', { class: 'plot', dataset: { kind: `warm-up-${sensor}` } });
      row.append(box);
      const channels = w.channels.map((c, i) => ({ c, i })).filter(({ c }) => c.sensor === sensor);
      const c = lineChart(box, { title, x: 'min since power-on', y: unit, height: 220, points: false,
        series: channels.flatMap(({ c: ch }, k) => [{ label: ch.axis, color: COLORS[k], width: 1 },
          { label: `${ch.axis} fit`, color: COLORS[k], width: 2, dash: [6, 4] }]) });
      c.setData([t_min, ...channels.flatMap(({ c: ch, i }) => [w.deviation[i],
        w.t_s.map((t) => (ch.detected ? ch.amplitude[0] * Math.exp(-t / ch.time_constant_s[0]) : 0))])]);
      cleanups.push(() => c.destroy());
    }
    return h('div', { id: 'warm-up' }, h('h3', {}, 'Warm-up: the bias transient from power-on (IEEE 952)'),
      h('p', { class: 'muted' }, `One static of ${duration(w.duration_s)} from power-on, averaged in bins and fitted with settled + amplitude · exp(−t / time constant) per channel. `,
        'Settled: the fitted transient stays inside the band from then on.'),
      table, row);
  }

  // Turn-on to turn-on repeatability (IEEE 952): per channel the 1-sigma bias change from one
  // power-on to the next with its intervals, and each power-on's bias against the mean.
  function repeatabilitySection(r) {
    const unitOfChannel = (c) => (c.unit === 'dph' ? '°/h' : 'µg');
    const range = ([lo, hi]) => `${num(lo, 3)} … ${num(hi, 3)}`;
    const table = h('table', { class: 'list compact', id: 'repeatability-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'channel'), h('th', { class: 'num' }, 'repeatability (1σ)'), h('th', { class: 'num' }, '68 % interval'),
        h('th', { class: 'num' }, '99.73 % interval'), h('th', { class: 'num' }, 'spread of the biases'), h('th', { class: 'num' }, 'noise in each'))),
      h('tbody', {}, ...r.channels.map((c) => h('tr', { dataset: { channel: `${c.sensor}.${c.axis}` } },
        h('td', {}, `${c.sensor === 'gyro' ? 'gyro' : 'accelerometer'} ${c.axis}`),
        h('td', { class: 'num' }, `${num(c.repeatability[0], 3)} ± ${num(c.repeatability[1], 2)} ${unitOfChannel(c)}`),
        h('td', { class: 'num' }, range(c.interval_68)), h('td', { class: 'num' }, range(c.interval_997)),
        h('td', { class: 'num' }, num(c.spread, 3)), h('td', { class: 'num' }, num(c.noise, 2))))));
    const row = h('div', { class: 'plot-row' });
    const index = r.turn_ons.map((t) => t.index);
    for (const [offset, title, unit] of [[0, 'Gyro bias at each power-on, less their mean', '°/h'], [3, 'Accelerometer bias at each power-on, less their mean', 'µg']]) {
      const box = h('div', { class: 'plot', dataset: { kind: `repeatability-${offset ? 'accel' : 'gyro'}` } });
      row.append(box);
      const c = lineChart(box, { title, x: 'power-on', y: unit, height: 200, points: true,
        series: ['x', 'y', 'z'].map((a, i) => ({ label: a, color: COLORS[i], width: 1 })) });
      c.setData([index, ...[0, 1, 2].map((j) => r.turn_ons.map((t) => t.offset[offset + j]))]);
      cleanups.push(() => c.destroy());
    }
    return h('div', { id: 'repeatability' }, h('h3', {}, 'Turn-on to turn-on bias repeatability (IEEE 952)'),
      h('p', { class: 'muted' }, `${r.turn_ons.length} power-ons at one orientation, each a static after its settle time. `,
        'The repeatability is the spread of their biases less the noise within each static; a standard deviation from a few power-ons is uncertain, hence the intervals (chi-square).'),
      table, row);
  }

  // ---- record: segments, transitions, events, spec ----

  function renderRecord() {
    const d = detail;
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
          onError: (a, e) => { pageError.textContent = `Alarm ${a.id}: ${e.message}`; refresh(); } })
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

// Events carry the segment's index (0-based, as in the daemon's own texts); its name says more.
function segmentName(d, index) {
  if (index === null || index === undefined) return '—';
  const s = (d.segments || [])[index];
  return s ? `${s.name} (${index})` : String(index);
}

function saveJson(filename, data) {
  const url = URL.createObjectURL(new Blob([JSON.stringify(data, null, 1)], { type: 'application/json' }));
  const a = h('a', { href: url, download: filename });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}
