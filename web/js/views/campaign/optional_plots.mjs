// The results' noise, thermal and navigation evaluation: the Allan deviation, the coefficients
// against temperature and the Schuler test, each computed by imucald from the recording (or what
// the run would need for it). modelNoise: the run's model, for the Allan panel's comparison;
// the charts' destroy functions go into cleanups (the page's).
import { get, ApiError } from '../../api.mjs';
import { h, num } from '../../format.mjs';
import { unitOf } from '../../coefficients.mjs';
import { lineChart, COLORS } from '../../plots.mjs';

// Each panel asks imucald for its data; a run that cannot give it gets the daemon's reason
// ({"available": false, "reason": "not available for this run: needs program ..."}, a 200, so
// that the browser logs no error), shown in the panel.
export async function optionalPlots(box, { id, detail, isStopped, cleanups, modelNoise }) {
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
        if (isStopped()) return false;
        note.textContent = p?.state === 'queued' ? `Queued behind ${Math.max(0, (p.queue_position ?? 1) - 1)} other computation(s)…`
          : `Computing from the recording… ${Math.round(100 * (p?.progress ?? 0))} %`;
        note.dataset.progress = String(p?.progress ?? 0);
        return true;
      } });
      if (isStopped()) return;
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
      s.render(el, data, { cleanups, modelNoise });
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

function renderAllan(el, data, { cleanups, modelNoise }) {
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

function renderThermal(el, data, { cleanups }) {
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

function renderEvaluation(el, data, { cleanups }) {
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
