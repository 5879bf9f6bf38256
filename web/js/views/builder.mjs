// The campaign builder: start from a built-in program (GET /api/programs), edit its segments and
// the chamber profile, and see the daemon's verdict (POST /api/campaigns/validate) beside the
// segment it concerns while typing. Fields are checked here first (a number where a number
// belongs, required keys per segment type), so nothing malformed is sent; the limits (rates,
// accelerations, angles, chamber, duration, estimator prerequisites) are the daemon's to judge.
// The draft is kept in sessionStorage, so a reload or a sign-in on the way loses nothing.
// The page composes the cards of views/builder/ around one state object (the draft, imucald's
// programs and limits, the fields' errors, the last check); this module loads them and runs the
// check after each edit.
import { get, post, ApiError } from '../api.mjs';
import { h, clear, duration } from '../format.mjs';
import { onSessionChange } from '../session.mjs';
import { canonical } from '../program_edit.mjs';
import { builderState } from './builder/state.mjs';
import { fieldErrors } from './builder/form.mjs';
import { readDraft, saveDraft, templateDraft, campaignBody, clientProblems } from './builder/draft.mjs';
import { campaignFields } from './builder/campaign_fields.mjs';
import { unitFields } from './builder/unit_fields.mjs';
import { chamberFields } from './builder/chamber_fields.mjs';
import { faultFields } from './builder/fault_fields.mjs';
import { segmentTable } from './builder/segment_table.mjs';
import { checkPanel } from './builder/check_panel.mjs';
import { planPanel } from './builder/plan_panel.mjs';
import { submitCampaign } from './builder/submit.mjs';

export function mount(root, ctx) {
  const state = builderState();
  let validateTimer = null;
  let validateSeq = 0;
  const body = () => campaignBody(state.draft);
  const form = { ...fieldErrors(root, state), changed, modified };

  const pageError = h('div', { class: 'form-error', role: 'alert', id: 'builder-error' });
  const templateSelect = h('select', { id: 'template' });
  const templateInfo = h('p', { class: 'muted', id: 'template-info' });
  const campaign = campaignFields(state, form);
  const unit = unitFields(state, form);
  const chamber = chamberFields(state, form);
  const faults = faultFields(state, form);
  const segments = segmentTable(state, form);
  // The prediction (POST /api/campaigns/plan): the program simulated with the unit's noise through
  // the calibration stages, redone a moment after each valid edit.
  const plan = planPanel(state, { body });
  const check = checkPanel(root, state, {
    onInvalid: () => plan.invalid(),
    onSubmit: (andStart) => submitCampaign(andStart, { state, check, navigate: (hash) => ctx.navigate(hash) }),
  });

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'New campaign'),
      h('div', { class: 'actions' },
        h('label', { for: 'template' }, 'Start from'), templateSelect,
        h('button', { type: 'button', id: 'load-template', onclick: () => loadTemplate(templateSelect.value, true) }, 'Load'),
        h('button', { type: 'button', id: 'reset-draft', class: 'link', onclick: () => loadTemplate(state.draft?.template || templateSelect.value, true) }, 'Reset'))),
    pageError,
    h('div', { class: 'builder' },
      h('div', { class: 'builder-main' },
        h('section', { class: 'card' }, h('h2', {}, 'Campaign'), templateInfo, campaign.element),
        h('section', { class: 'card', dataset: { field: 'imu' } }, h('h2', {}, 'Unit under test'), unit.element, unit.serialList),
        h('section', { class: 'card' }, h('h2', {}, 'Chamber profile'), chamber.element),
        h('section', { class: 'card', dataset: { field: 'sim_faults' } }, h('h2', {}, 'Simulated faults (tests and demonstrations)'), faults.element),
        segments.element),
      h('aside', { class: 'builder-side card' }, ...check.nodes, ...plan.nodes)));

  const offSession = onSessionChange(() => check.updateRoleUi());

  // ---- loading ----

  (async () => {
    try {
      const [p, status] = await Promise.all([get('/api/programs'), ctx.status()]);
      if (state.destroyed) return;
      state.programs = p.programs || [];
      unit.loadUnits();
      state.limits = status.limits || null;
      state.devices = status.devices || null;
      const programs = state.programs;
      clear(templateSelect).append(...programs.map((pr) => h('option', { value: pr.name }, `${pr.name} (${duration(pr.duration_s)})`)));
      const saved = readDraft();
      const wanted = ctx.params.template;
      if (saved && (!wanted || wanted === saved.template)) {
        state.draft = saved;
        templateSelect.value = state.draft.template || programs[0]?.name;
        renderAll();
      } else {
        loadTemplate(wanted && programs.some((x) => x.name === wanted) ? wanted : (programs.find((x) => x.name === 'direct-short') || programs[0])?.name, false);
      }
    } catch (e) {
      pageError.textContent = `Cannot load the built-in programs: ${e.message}`;
    }
  })();

  function loadTemplate(name, confirmLoss) {
    const p = state.programs.find((x) => x.name === name);
    if (!p) return;
    if (confirmLoss && state.draft?.modified && !window.confirm('Replace the edited segments with the built-in program?')) return;
    templateSelect.value = name;
    state.draft = templateDraft(p, state.limits);
    state.fieldErrors = new Map();
    renderAll();
  }

  function renderAll() {
    const draft = state.draft;
    const p = state.programs.find((x) => x.name === draft.template);
    clear(templateInfo).append(
      p ? `Built-in program "${p.name}": ${p.program?.comment || ''} ${p.segments.length} segments, ${duration(p.duration_s)}.` : '',
      draft.modified ? h('strong', { class: 'modified' }, ' Edited: sent as an inline program.') : '');
    campaign.render();
    unit.render();
    chamber.render();
    faults.render();
    segments.render();
    changed(false);
  }

  // ---- state changes ----

  // Edited means different from the built-in program: an edit undone by hand is no edit, and the
  // campaign names the built-in program again.
  function modified() {
    const draft = state.draft;
    const template = state.programs.find((x) => x.name === draft.template);
    draft.modified = !template || canonical(draft.program) !== canonical(template.program);
    const mark = templateInfo.querySelector('.modified');
    if (draft.modified && !mark) templateInfo.append(h('strong', { class: 'modified' }, ' Edited: sent as an inline program.'));
    if (!draft.modified) mark?.remove();
    changed();
  }

  function changed(save = true) {
    if (save) saveDraft(state.draft);
    check.showJson(body());
    check.say('');
    clearTimeout(validateTimer);
    plan.edited();
    const local = clientProblems(state.draft, state.fieldErrors);
    if (local.length) {
      state.validation = { state: 'local', problems: local, duration_s: null, segments: [] };
      check.render();
      return;
    }
    state.validation = { ...state.validation, state: 'checking' };
    check.render();
    validateTimer = setTimeout(validate, 350);
  }

  async function validate() {
    const seq = ++validateSeq;
    try {
      const r = await post('/api/campaigns/validate', body());
      if (seq !== validateSeq || state.destroyed) return;  // a newer edit is being checked
      state.validation = { state: r.valid ? 'valid' : 'invalid', problems: r.problems || [], duration_s: r.duration_s, segments: r.segments || [] };
      if (r.valid) plan.schedule();
    } catch (e) {
      if (seq !== validateSeq || state.destroyed) return;
      state.validation = { state: 'error', problems: e instanceof ApiError ? (e.problems.length ? e.problems : [e.message]) : [String(e)], duration_s: null, segments: [] };
    }
    check.render();
  }

  return () => {
    state.destroyed = true;
    clearTimeout(validateTimer);
    plan.destroy();
    offSession();
  };
}
