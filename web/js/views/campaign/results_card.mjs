// A campaign's results: the downloads, the coefficient table and the verdict, what each stage
// contributed, the tests' sections (rate steps, tumble, warm-up, repeatability), what the
// estimators said, the convergence, the run's recording and the noise, thermal and navigation
// evaluation. Each is a component of this folder; this one reads what they need and lays them out.
import { get } from '../../api.mjs';
import { h, clear, num } from '../../format.mjs';
import { recordingPlots } from '../../recording_plots.mjs';
import { downloads } from './downloads.mjs';
import { coefficientTable } from './coefficient_table.mjs';
import { verdictSection } from './verdict_section.mjs';
import { contributionsTable } from './contributions_table.mjs';
import { rateStepsSection } from './rate_steps_section.mjs';
import { tumbleSection } from './tumble_section.mjs';
import { warmUpSection } from './warm_up_section.mjs';
import { repeatabilitySection } from './repeatability_section.mjs';
import { stageNotes } from './stage_notes.mjs';
import { resultsConvergence } from './results_convergence.mjs';
import { optionalPlots } from './optional_plots.mjs';

/** The card, hidden until load(d) draws campaign d's results. The page's: status() (imucald's),
 *  getDetail() the campaign as last read, isStopped() once it was left, onError(text),
 *  onAccepted() after a partial run was accepted, cleanups (the charts' destroy functions). */
export function resultsCard({ id, status, getDetail, isStopped, onError, onAccepted, cleanups }) {
  const results = h('section', { class: 'card', id: 'results', hidden: true });

  // Which load draws: a later load (the run ended while a partial run's results were being read)
  // supersedes one still waiting for its data, which then stops instead of adding its own rows
  // (a second download row, drawn for the state the run had then) to the card.
  let latest = 0;
  async function load(d) {
    const mine = ++latest;
    const superseded = () => isStopped() || mine !== latest;
    results.hidden = false;
    clear(results).append(h('h2', {}, 'Results'));
    // The truth of a simulated run in the model's frame (imucald turns it, written in the
    // instrument frame, into a body-frame model's frame): asked only when the run has both.
    const hasTruth = d.spec && typeof d.spec.truth === 'object' && d.spec.truth !== null;
    const [model, progress, daemonStatus, comparison] = await Promise.all([
      d.has_model ? get(`/api/campaigns/${id}/model`).catch((e) => ({ _error: e })) : null,
      get(`/api/campaigns/${id}/progress`).catch(() => null),
      status().catch(() => null),
      d.has_model && hasTruth ? get(`/api/campaigns/${id}/truth`).catch(() => null) : null,
    ]);
    if (superseded()) return;
    // The run's model, for the Allan panel's comparison.
    const modelNoise = model && !model._error ? model : null;
    const truth = comparison && Array.isArray(comparison.rows) ? comparison : null;
    const simulated = (daemonStatus?.devices || '').startsWith('sim') || hasTruth;

    results.append(downloads(d, { id, getDetail, isStopped: superseded, onError, onAccepted }));

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
      if (superseded()) return;
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
    if (rateSteps?.axes?.length) results.append(rateStepsSection(rateSteps, cleanups));
    const tumble = d.results?.tumble?.tumble;
    if (tumble?.positions?.length) results.append(tumbleSection(tumble, cleanups));
    const warmUp = d.results?.['warm-up']?.warm_up;
    if (warmUp?.channels?.length) results.append(warmUpSection(warmUp, cleanups));
    const repeat = d.results?.repeatability?.repeatability;
    if (repeat?.channels?.length) results.append(repeatabilitySection(repeat, cleanups));

    // What the estimators said
    const notes = stageNotes(d.results);
    if (notes) results.append(h('h3', {}, 'Estimators'), notes);

    // Convergence over the run
    resultsConvergence(results, progress, cleanups);

    // The run itself, from its recording: table, rates and temperatures, zoomable.
    if (d.run_db) {
      const box = h('div', { class: 'recording-plots', id: 'recording-plots' });
      results.append(h('h3', {}, 'The run: table, IMU and temperatures from the recording'), box);
      cleanups.push(recordingPlots(box, id));
    }

    // Plots whose data the API may provide (docs/web.md lists what it lacks today).
    const optional = h('div', { class: 'optional-plots', id: 'optional-plots' });
    results.append(h('h3', {}, 'Noise, thermal and navigation evaluation'), optional);
    await optionalPlots(optional, { id, detail: getDetail(), isStopped: superseded, cleanups, modelNoise });
  }
  return { element: results, load };
}
