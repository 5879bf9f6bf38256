// The builder's predicted accuracy (POST /api/campaigns/plan): the program simulated with the
// unit's noise through the calibration stages, redone a moment after each valid edit, judged
// against 1-sigma targets the operator may change (prediction_view.mjs lays it out).
import { post } from '../../api.mjs';
import { h, clear } from '../../format.mjs';
import { parseNumber } from '../../program_edit.mjs';
import { seedTargets } from '../../plan.mjs';
import { showPrediction } from './prediction_view.mjs';

// The prediction's unit noise and targets outlive a draft: they describe the lab's units.
const PLAN_KEY = 'imucal.builder.plan';
// The targets are imucald's (GET /api/schema), known once signed in: asked for when a page mounts.
const planDefaults = () => ({ arw_deg_rth: 0.0005, vrw_mps_rth: 0.002, targets: seedTargets() });

function targetId(group) { return `target-${group.replace(/\./g, '-')}`; }

function loadPlanSettings() {
  try {
    const saved = JSON.parse(localStorage.getItem(PLAN_KEY) || 'null');
    if (saved && typeof saved === 'object')
      return { ...planDefaults(), ...saved, targets: { ...seedTargets(), ...(saved.targets || {}) } };
  } catch { /* unreadable: the defaults */ }
  return planDefaults();
}

/** The side panel's part: nodes to lay out; edited() after any edit, schedule() once imucald
 *  found the campaign valid, invalid() once it is not, destroy(). body() is the campaign JSON. */
export function planPanel(state, { body }) {
  let planTimer = null;
  let planSeq = 0;
  let lastPrediction = null;
  let planSettings = loadPlanSettings();
  const planStatus = h('p', { class: 'plan-status', id: 'plan-status', 'aria-live': 'polite' }, 'Predicted once the campaign is valid.');
  const planBody = h('tbody', { id: 'plan-rows' });
  const planWeak = h('ul', { class: 'problems', id: 'plan-weak' });
  // Stage 1's budget (issue 34): the table accuracy the program needs for stage 1's limits.
  const planBench = h('div', { id: 'plan-bench' });
  const planTable = h('table', { class: 'plan-table', id: 'plan-table' },
    h('colgroup', {}, h('col', { class: 'c-name' }), h('col', { class: 'c-sigma' }), h('col', { class: 'c-target' }),
      h('col', { class: 'c-dominant' })),
    h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient (stage)'), h('th', { class: 'num' }, '1σ'), h('th', { class: 'num' }, 'Target'),
      h('th', {}, 'Limited by'))),
    planBody);
  const els = { planStatus, planTable, planBody, planBench, planWeak };
  const planNoise = h('div', { class: 'grid-form', id: 'plan-noise' },
    h('label', { for: 'plan-arw' }, 'Gyro ARW, deg/√h'),
    h('input', { id: 'plan-arw', inputmode: 'decimal', value: String(planSettings.arw_deg_rth), onchange: planInputChanged }),
    h('label', { for: 'plan-vrw' }, 'Accel VRW, m/s/√h'),
    h('input', { id: 'plan-vrw', inputmode: 'decimal', value: String(planSettings.vrw_mps_rth), onchange: planInputChanged }));
  const planTargets = h('div', { class: 'grid-form', id: 'plan-targets' },
    ...Object.entries(seedTargets()).flatMap(([g, seed]) => [
      h('label', { for: targetId(g) }, g),
      h('input', { id: targetId(g), inputmode: 'decimal', value: String(planSettings.targets[g] ?? seed), onchange: planInputChanged })]));
  const settings = h('details', { id: 'plan-settings' }, h('summary', {}, 'Unit noise and 1-sigma targets (default: the seed\'s figures)'),
    planNoise, planTargets);
  const show = (p) => showPrediction(els, p, planSettings.targets, state.draft.campaign.rate_hz);

  // The noise inputs change the prediction (asked again); the targets only its verdicts.
  function planInputChanged() {
    // parseNumber answers {value} or {empty}/{error}: a field that is not a number reads as NaN.
    const read = (id) => parseNumber(settings.querySelector(`#${id}`).value).value ?? NaN;
    const arw = read('plan-arw'), vrw = read('plan-vrw');
    const targets = {};
    for (const g of Object.keys(seedTargets())) {
      const t = read(targetId(g));
      if (Number.isFinite(t) && t > 0) targets[g] = t;
    }
    if (!(arw > 0) || !(vrw > 0)) {
      planStatus.textContent = 'The unit noise must be two positive numbers.';
      planStatus.dataset.state = 'error';
      return;
    }
    const noiseChanged = arw !== planSettings.arw_deg_rth || vrw !== planSettings.vrw_mps_rth;
    planSettings = { arw_deg_rth: arw, vrw_mps_rth: vrw, targets };
    try { localStorage.setItem(PLAN_KEY, JSON.stringify(planSettings)); } catch { /* private mode */ }
    if (noiseChanged && state.validation.state === 'valid') schedule();
    else if (lastPrediction) show(lastPrediction);
  }

  function schedule() {
    clearTimeout(planTimer);
    planTimer = setTimeout(predict, 600);
  }

  async function predict() {
    const seq = ++planSeq;
    planStatus.dataset.state = 'checking';
    planStatus.textContent = 'Predicting…';
    const request = { ...body(), plan: { arw_deg_rth: planSettings.arw_deg_rth, vrw_mps_rth: planSettings.vrw_mps_rth } };
    try {
      const r = await post('/api/campaigns/plan', request, { onPending: (p) => {
        if (seq !== planSeq || state.destroyed) return false;  // edited since: this one is no longer wanted
        planStatus.textContent = `Predicting… ${Math.round(100 * (p.progress || 0))} %`;
        return true;
      } });
      if (seq !== planSeq || state.destroyed) return;
      lastPrediction = r;
      show(r);
    } catch (e) {
      if (seq !== planSeq || state.destroyed) return;
      clearPrediction('error', `No prediction: ${e.message}`);
    }
  }

  function clearPrediction(status, text) {
    lastPrediction = null;
    clear(planBody);
    clear(planWeak);
    clear(planBench);
    delete planTable.dataset.stale;
    planStatus.dataset.state = status;
    planStatus.textContent = text;
  }

  function edited() {
    clearTimeout(planTimer);
    planSeq++;  // a prediction under way is for the previous program
    // The prediction on show is the previous campaign's: marked so at once (greyed, its status
    // saying so), and taken away if the edit makes the campaign invalid (invalid()).
    if (lastPrediction) {
      planStatus.dataset.state = 'checking';
      planStatus.textContent = 'Edited: predicted again once the campaign is valid.';
      planTable.dataset.stale = 'true';
    }
  }

  function invalid() {
    if (lastPrediction || planTable.dataset.stale)
      clearPrediction('idle', 'No prediction while the campaign is invalid: predicted again once it is valid.');
  }

  return {
    nodes: [h('h2', {}, 'Predicted accuracy'), planStatus, settings, planTable, planBench, planWeak],
    edited, schedule, invalid, destroy: () => clearTimeout(planTimer),
  };
}
