// The campaign builder: start from a built-in program (GET /api/programs), edit its segments and
// the chamber profile, and see the daemon's verdict (POST /api/campaigns/validate) beside the
// segment it concerns while typing. Fields are checked here first (a number where a number
// belongs, required keys per segment type), so nothing malformed is sent; the limits (rates,
// accelerations, angles, chamber, duration, estimator prerequisites) are the daemon's to judge.
// The draft is kept in sessionStorage, so a reload or a sign-in on the way loses nothing.
import { get, post, ApiError } from '../api.mjs';
import { h, clear, duration, num } from '../format.mjs';
import { isOperator, onSessionChange } from '../session.mjs';
import { confirmDialog, startCampaign } from '../dialogs.mjs';
import { SEGMENT_TYPES, NEW_SEGMENT, AXIS_NAMES, parseNumber, parseField, formatValue, mapProblems, sourceIndex, compress, canonical, campaignFieldLabel, problemForPeople } from '../program_edit.mjs';
import { seedTargets, predictionRows, summary, dominantSources, benchRequirements } from '../plan.mjs';
import { sourceName } from '../budget.mjs';
import { truthChoices, defaultTruth, parseTruthFile, truthLabel } from '../truths.mjs';

// The truth select's choice that uploads a model file.
const UPLOAD = '__upload__';

const DRAFT_KEY = 'imucal.builder.draft';
// The prediction's unit noise and targets outlive a draft: they describe the lab's units.
const PLAN_KEY = 'imucal.builder.plan';
// The targets are imucald's (GET /api/schema), known once signed in: asked for when a page mounts.
const planDefaults = () => ({ arw_deg_rth: 0.0005, vrw_mps_rth: 0.002, targets: seedTargets() });
const FAULT_KINDS = ['chamber_offset', 'imu_dropout', 'imu_corrupt', 'imu_drop', 'disconnect', 'table_fault', 'disk_full'];
const FAULT_EXTRA = { chamber_offset: { offset_C: 6 }, imu_corrupt: { frames: 10 }, imu_drop: { frames: 10 }, disconnect: { device: 'imu' } };

// ---- the view ---------------------------------------------------------------------------------

// A text field narrower than what it may hold ("lever-arm/static-x-up", "0, 54.735610317245346, 45")
// keeps its whole value in its tooltip.
function titled(input) {
  input.title = input.value;
  input.addEventListener('input', () => { input.title = input.value; });
  return input;
}

export function mount(root, ctx) {
  let programs = [];
  let units = [];            // GET /api/imus: the serials already known, offered as you type
  let limits = null;
  let devices = null;  // GET /api/status: sim, sim-wire or real
  let draft = null;          // {template, modified, campaign: {...}, program: {...}}
  let fieldErrors = new Map();  // input id -> message (client-side)
  let validation = { state: 'idle', problems: [], duration_s: null, segments: [] };
  let validateTimer = null;
  let validateSeq = 0;
  let planTimer = null;
  let planSeq = 0;
  let lastPrediction = null;
  let planSettings = loadPlanSettings();
  let destroyed = false;

  const pageError = h('div', { class: 'form-error', role: 'alert', id: 'builder-error' });
  const templateSelect = h('select', { id: 'template' });
  const templateInfo = h('p', { class: 'muted', id: 'template-info' });
  const campaignBox = h('div', { class: 'grid-form', id: 'campaign-fields' });
  const unitBox = h('div', { class: 'grid-form', id: 'unit-fields' });
  const serialList = h('datalist', { id: 'known-serials' });
  const chamberBox = h('div', { id: 'chamber-fields' });
  const faultsBox = h('div', { id: 'fault-fields' });
  const segmentsBody = h('tbody', { id: 'segments' });
  const verdict = h('div', { class: 'verdict', id: 'verdict', 'aria-live': 'polite' });
  const problemsList = h('ul', { class: 'problems', id: 'problems' });
  const serverMessage = h('div', { class: 'form-error', role: 'alert', id: 'server-message' });
  const preview = h('pre', { class: 'json-preview', id: 'json-preview' });
  const createButton = h('button', { type: 'button', id: 'create', class: 'operator-only' }, 'Create campaign');
  const startButton = h('button', { type: 'button', id: 'create-start', class: 'primary operator-only' }, 'Create and start…');
  const viewerNote = h('p', { class: 'hint viewer-only' }, 'You are signed in as a viewer: you can build and check a campaign, but only an operator can create or start one.');
  // The prediction (POST /api/campaigns/plan): the program simulated with the unit's noise through
  // the calibration stages, redone a moment after each valid edit.
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
  const planNoise = h('div', { class: 'grid-form', id: 'plan-noise' },
    h('label', { for: 'plan-arw' }, 'Gyro ARW, deg/√h'),
    h('input', { id: 'plan-arw', inputmode: 'decimal', value: String(planSettings.arw_deg_rth), onchange: planInputChanged }),
    h('label', { for: 'plan-vrw' }, 'Accel VRW, m/s/√h'),
    h('input', { id: 'plan-vrw', inputmode: 'decimal', value: String(planSettings.vrw_mps_rth), onchange: planInputChanged }));
  const planTargets = h('div', { class: 'grid-form', id: 'plan-targets' },
    ...Object.entries(seedTargets()).flatMap(([g, seed]) => [
      h('label', { for: targetId(g) }, g),
      h('input', { id: targetId(g), inputmode: 'decimal', value: String(planSettings.targets[g] ?? seed), onchange: planInputChanged })]));

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'New campaign'),
      h('div', { class: 'actions' },
        h('label', { for: 'template' }, 'Start from'), templateSelect,
        h('button', { type: 'button', id: 'load-template', onclick: () => loadTemplate(templateSelect.value, true) }, 'Load'),
        h('button', { type: 'button', id: 'reset-draft', class: 'link', onclick: () => loadTemplate(draft?.template || templateSelect.value, true) }, 'Reset'))),
    pageError,
    h('div', { class: 'builder' },
      h('div', { class: 'builder-main' },
        h('section', { class: 'card' }, h('h2', {}, 'Campaign'), templateInfo, campaignBox),
        h('section', { class: 'card', dataset: { field: 'imu' } }, h('h2', {}, 'Unit under test'), unitBox, serialList),
        h('section', { class: 'card' }, h('h2', {}, 'Chamber profile'), chamberBox),
        h('section', { class: 'card', dataset: { field: 'sim_faults' } }, h('h2', {}, 'Simulated faults (tests and demonstrations)'), faultsBox),
        h('section', { class: 'card' },
          h('div', { class: 'section-head' }, h('h2', {}, 'Program segments'),
            h('div', { class: 'actions' }, h('label', { for: 'add-type' }, 'Add'),
              h('select', { id: 'add-type' }, ...Object.keys(SEGMENT_TYPES).map((t) => h('option', { value: t }, t))),
              h('button', { type: 'button', id: 'add-segment', onclick: () => addSegment(root.querySelector('#add-type').value) }, 'Add segment'))),
          h('table', { class: 'segments' },
            h('thead', {}, h('tr', {}, h('th', {}, '#'), h('th', {}, 'Name'), h('th', {}, 'Type'), h('th', {}, 'Parameters'),
              h('th', { class: 'num' }, 'Time'), h('th', {}, ''))),
            segmentsBody))),
      h('aside', { class: 'builder-side card' },
        h('h2', {}, 'Check'), verdict, problemsList, serverMessage, viewerNote,
        h('div', { class: 'actions' }, createButton, startButton),
        h('details', {}, h('summary', {}, 'JSON sent to imucald'), preview),
        h('h2', {}, 'Predicted accuracy'), planStatus,
        h('details', { id: 'plan-settings' }, h('summary', {}, 'Unit noise and 1-sigma targets (default: the seed\'s figures)'),
          planNoise, planTargets),
        planTable,
        planBench,
        planWeak)));

  createButton.addEventListener('click', () => submit(false));
  startButton.addEventListener('click', () => submit(true));
  const offSession = onSessionChange(() => updateRoleUi());

  // ---- loading ----

  (async () => {
    try {
      const [p, status] = await Promise.all([get('/api/programs'), ctx.status()]);
      if (destroyed) return;
      programs = p.programs || [];
      loadUnits();
      limits = status.limits || null;
      devices = status.devices || null;
      clear(templateSelect).append(...programs.map((pr) => h('option', { value: pr.name }, `${pr.name} (${duration(pr.duration_s)})`)));
      const saved = readDraft();
      const wanted = ctx.params.template;
      if (saved && (!wanted || wanted === saved.template)) {
        draft = saved;
        templateSelect.value = draft.template || programs[0]?.name;
        renderAll();
      } else {
        loadTemplate(wanted && programs.some((x) => x.name === wanted) ? wanted : (programs.find((x) => x.name === 'direct-short') || programs[0])?.name, false);
      }
    } catch (e) {
      pageError.textContent = `Cannot load the built-in programs: ${e.message}`;
    }
  })();

  // The known serials: a failure only loses the suggestions, never the builder.
  async function loadUnits() {
    try {
      const r = await get('/api/imus');
      if (destroyed) return;
      units = r.imus || [];
      clear(serialList).append(...units.map((u) => h('option', { value: u.serial },
        [u.part_number, `${u.calibrations} calibration${u.calibrations === 1 ? '' : 's'}`].filter(Boolean).join(', '))));
    } catch {
      units = [];
    }
  }

  function readDraft() {
    try {
      const d = JSON.parse(sessionStorage.getItem(DRAFT_KEY) || 'null');
      return d && d.campaign && d.program && Array.isArray(d.program.segments) ? d : null;
    } catch {
      return null;
    }
  }

  function saveDraft() {
    try { sessionStorage.setItem(DRAFT_KEY, JSON.stringify(draft)); } catch { /* private mode: no draft */ }
  }

  function loadTemplate(name, confirmLoss) {
    const p = programs.find((x) => x.name === name);
    if (!p) return;
    if (confirmLoss && draft?.modified && !window.confirm('Replace the edited segments with the built-in program?')) return;
    templateSelect.value = name;
    const known = limits?.campaign?.estimators || [];
    draft = {
      template: name,
      modified: false,
      campaign: {
        name: `${name} check`,
        // The estimators a campaign of this program runs by default (imucald's campaign check
        // chooses them from the program's parts: GET /api/programs).
        estimators: (p.estimators || []).filter((e) => known.includes(e)),
        rate_hz: 100,
        time_scale: 10,
        seed: 1,
        truth: defaultTruth(limits?.campaign?.truths),
        // A thermal program brings its chamber profile; the others hold the safe set point.
        chamber: p.chamber ? structuredClone(p.chamber)
          : { setpoint_C: limits?.chamber?.safe_setpoint_C ?? 25, tolerance_C: limits?.chamber?.tolerance_C ?? 2, steps: [] },
      },
      program: structuredClone(p.program),
    };
    fieldErrors = new Map();
    renderAll();
  }

  // ---- rendering ----

  // The unit (campaign.imu): a serial picked from the known ones brings its part number.
  function renderUnit() {
    const u = draft.campaign.imu || (draft.campaign.imu = {});
    clear(unitBox);
    const text = (id, key, attrs = {}) => {
      const el = input(id, `imu.${key}`, u[key], { type: 'text', maxlength: 2000, ...attrs });
      el.addEventListener('input', () => {
        u[key] = el.value;
        if (key === 'serial') {
          const known = units.find((x) => x.serial === el.value.trim());
          const partEl = unitBox.querySelector('#c-imu-part');
          if (known && partEl && !partEl.value.trim() && known.part_number) {
            partEl.value = known.part_number;
            u.part_number = known.part_number;
          }
        }
        setError(unitBox.querySelector('#c-imu-serial'), serialProblem(u));
        changed();
      });
      return el;
    };
    const serial = text('c-imu-serial', 'serial', { maxlength: 64, list: 'known-serials', autocomplete: 'off', placeholder: 'FOG-0042' });
    const notes = h('textarea', { id: 'c-imu-notes', dataset: { path: 'imu.notes' }, rows: 2, maxlength: 2000 });
    notes.value = u.notes || '';
    notes.addEventListener('input', () => { u.notes = notes.value; changed(); });
    unitBox.append(
      fieldRow(campaignFieldLabel('imu.serial'), serial, 'imu.serial', 'the unit\'s serial number; known serials are offered as you type'),
      fieldRow(campaignFieldLabel('imu.part_number'), text('c-imu-part', 'part_number'), 'imu.part_number'),
      fieldRow(campaignFieldLabel('imu.firmware'), text('c-imu-firmware', 'firmware'), 'imu.firmware'),
      fieldRow(campaignFieldLabel('imu.customer'), text('c-imu-customer', 'customer'), 'imu.customer'),
      fieldRow(campaignFieldLabel('imu.notes'), notes, 'imu.notes'));
    setError(serial, serialProblem(u));
  }

  /** What is wrong with the unit's serial as typed (the daemon checks the same). */
  function serialProblem(u) {
    const serial = (u.serial || '').trim();
    const others = ['part_number', 'firmware', 'customer', 'notes'].some((k) => (u[k] || '').trim());
    if (!serial) return others ? 'The unit needs a serial.' : null;
    if (serial.length > 64 || /[\/\\\u0000-\u001f\u007f]/.test(serial) || /^\.+$/.test(serial))
      return 'At most 64 printable characters, no slash, not only dots.';
    return null;
  }

  function renderAll() {
    const p = programs.find((x) => x.name === draft.template);
    clear(templateInfo).append(
      p ? `Built-in program "${p.name}": ${p.program?.comment || ''} ${p.segments.length} segments, ${duration(p.duration_s)}.` : '',
      draft.modified ? h('strong', { class: 'modified' }, ' Edited: sent as an inline program.') : '');
    renderCampaign();
    renderUnit();
    renderChamber();
    renderFaults();
    renderSegments();
    changed(false);
  }

  function input(id, path, value, attrs = {}) {
    const el = h('input', { id, dataset: { path }, value: value ?? '', ...attrs });
    return el;
  }

  function fieldRow(label, control, path, hint) {
    return h('div', { class: 'field', dataset: { field: path } },
      h('label', { for: control.id }, label), control,
      hint ? h('span', { class: 'hint' }, hint) : null,
      h('div', { class: 'field-error', id: `${control.id}-error`, role: 'alert' }));
  }

  function renderCampaign() {
    const c = draft.campaign;
    clear(campaignBox);
    const name = input('c-name', 'name', c.name, { type: 'text', maxlength: 200, required: true });
    name.addEventListener('input', () => { setCampaign('name', name.value, name.value.trim() ? null : 'A campaign needs a name.', name); });
    const known = limits?.campaign?.estimators || ['direct', 'navigation'];
    const est = h('div', { class: 'checks', id: 'c-estimators', dataset: { path: 'estimators' } },
      ...known.map((e) => {
        const cb = h('input', { type: 'checkbox', id: `c-est-${e}`, value: e, checked: c.estimators.includes(e) });
        cb.addEventListener('change', () => {
          c.estimators = known.filter((k) => root.querySelector(`#c-est-${k}`).checked);
          changed();
        });
        return h('label', { class: 'check' }, cb, ` ${e}`);
      }));
    const numberInput = (id, key, hint, check) => {
      const el = input(id, key, c[key], { type: 'text', inputmode: 'decimal', class: 'short' });
      el.addEventListener('input', () => {
        const r = parseNumber(el.value);
        let err = r.error || (r.empty ? null : check?.(r.value));
        setCampaign(key, r.empty ? undefined : r.value, err, el);
      });
      return fieldRow(campaignFieldLabel(key), el, key, hint);
    };
    const maxRate = limits?.campaign?.max_rate_hz;
    // The simulated IMU's truth: a name imucald offers (nav-grade by default) or a model file
    // uploaded from this computer, sent inline; never a path on the daemon's machine.
    const choices = truthChoices(limits?.campaign?.truths);
    // A draft naming a truth imucald does not offer (kept from before): shown as it is, and
    // imucald's answer names the ones it knows.
    if (typeof c.truth === 'string' && !choices.some((t) => t.name === c.truth))
      choices.push({ name: c.truth, description: 'not offered by imucald: choose another', builtin: false });
    const truthSel = h('select', { id: 'c-truth-kind', dataset: { path: 'truth' } },
      ...choices.map((t) => h('option', { value: t.name }, t.name === 'ideal' ? 'ideal (an error-free, noise-free IMU)' : t.name)),
      h('option', { value: UPLOAD }, 'a truth JSON file from this computer…'));
    const truthFile = h('input', { id: 'c-truth-file', type: 'file', accept: '.json,application/json', 'aria-label': 'truth file', dataset: { path: 'truth' } });
    const truthNote = h('span', { class: 'hint', id: 'c-truth-description' });
    const describe = () => {
      const chosen = choices.find((t) => t.name === truthSel.value);
      truthNote.textContent = truthSel.value === UPLOAD
        ? (c.truth && typeof c.truth === 'object' ? truthLabel(c.truth) : 'Choose an imucal-imu-model/1 file (instrument frame).')
        : chosen?.description || '';
    };
    truthSel.value = typeof c.truth === 'object' && c.truth !== null ? UPLOAD : typeof c.truth === 'string' ? c.truth : 'ideal';
    truthFile.hidden = truthSel.value !== UPLOAD;
    describe();
    truthSel.addEventListener('change', () => {
      truthFile.hidden = truthSel.value !== UPLOAD;
      if (truthSel.value !== UPLOAD) setCampaign('truth', truthSel.value, null, truthFile);
      else if (!(c.truth && typeof c.truth === 'object')) setError(truthFile, 'Choose a truth file to upload.');
      describe();
    });
    truthFile.addEventListener('change', async () => {
      const file = truthFile.files?.[0];
      if (!file) return;
      const r = parseTruthFile(await file.text(), file.name);
      if (destroyed) return;
      setCampaign('truth', r.model, r.error || null, truthFile);
      describe();
    });
    const simulatedNote = (devices || '').startsWith('sim')
      ? h('p', { class: 'muted', id: 'simulated-imu' }, `The IMU is simulated (devices: ${devices}): its errors and noise are the truth chosen here, and the results compare the calibration with it.`)
      : null;
    const truthField = h('div', { class: 'field', dataset: { field: 'truth' } }, h('label', { for: 'c-truth-kind' }, 'truth (simulated IMU)'),
      truthSel, truthFile, truthNote, h('div', { class: 'field-error', id: 'c-truth-file-error', role: 'alert' }), simulatedNote);

    campaignBox.append(
      fieldRow(campaignFieldLabel('name'), name, 'name'),
      h('div', { class: 'field', dataset: { field: 'estimators' } }, h('label', {}, 'estimators'), est,
        h('div', { class: 'field-error', id: 'c-estimators-error', role: 'alert' })),
      numberInput('c-rate', 'rate_hz', maxRate ? `IMU frames per second, ≤ ${maxRate}` : 'IMU frames per second',
        (v) => (v > 0 ? null : 'must be greater than 0')),
      numberInput('c-time-scale', 'time_scale', 'program seconds per wall second (simulation; 0: as fast as possible)',
        (v) => (v >= 0 ? null : 'must not be negative')),
      numberInput('c-seed', 'seed', 'simulation noise seed', (v) => (Number.isInteger(v) && v >= 0 ? null : 'a whole number ≥ 0')),
      truthField);
  }

  function renderChamber() {
    const ch = draft.campaign.chamber || (draft.campaign.chamber = { steps: [] });
    clear(chamberBox);
    const lim = limits?.chamber;
    const sp = input('ch-setpoint', 'chamber.setpoint_C', ch.setpoint_C, { type: 'text', inputmode: 'decimal', class: 'short' });
    const tol = input('ch-tolerance', 'chamber.tolerance_C', ch.tolerance_C, { type: 'text', inputmode: 'decimal', class: 'short' });
    sp.addEventListener('input', () => {
      const r = parseNumber(sp.value);
      setChamber('setpoint_C', r.empty ? undefined : r.value, r.error, sp);
    });
    tol.addEventListener('input', () => {
      const r = parseNumber(tol.value);
      setChamber('tolerance_C', r.empty ? undefined : r.value, r.error || (r.value !== undefined && !(r.value > 0) ? 'must be greater than 0' : null), tol);
    });
    const stepsBody = h('tbody', { id: 'chamber-steps' });
    (ch.steps || []).forEach((step, i) => {
      const cell = (key, label) => {
        const el = input(`ch-step-${i}-${key}`, `chamber.steps[${i}].${key}`, step[key], { type: 'text', inputmode: 'decimal', class: 'short', 'aria-label': `step ${i + 1} ${label}` });
        el.addEventListener('input', () => {
          const r = parseNumber(el.value);
          let err = r.error || (r.empty ? 'required' : null);
          if (!err && key !== 'setpoint_C' && r.value < 0) err = 'must not be negative';
          if (!err) step[key] = r.value;
          setError(el, err);
          changed();
        });
        return h('td', {}, el, h('div', { class: 'field-error', id: `${el.id}-error` }));
      };
      stepsBody.append(h('tr', { dataset: { field: `chamber.steps[${i}]` } },
        h('td', { class: 'num' }, i + 1), cell('at_s', 'at s'), cell('setpoint_C', 'set point °C'), cell('ramp_C_per_min', 'ramp °C/min'),
        h('td', {}, h('button', { type: 'button', class: 'link', 'aria-label': `remove step ${i + 1}`, onclick: () => {
          ch.steps.splice(i, 1);
          dropErrors('ch-step-');
          renderChamber();
          changed();
        } }, 'remove'))));
    });
    chamberBox.append(
      h('div', { class: 'grid-form' },
        fieldRow(campaignFieldLabel('chamber.setpoint_C'), sp, 'chamber.setpoint_C', lim ? `${lim.min_C} … ${lim.max_C} °C; empty: hold the safe set point ${lim.safe_setpoint_C} °C` : ''),
        fieldRow(campaignFieldLabel('chamber.tolerance_C'), tol, 'chamber.tolerance_C', 'a reading outside set point ± tolerance suspends the run')),
      ch.steps?.length ? h('table', { class: 'steps' },
        h('thead', {}, h('tr', {}, h('th', {}, '#'), h('th', {}, 'at program time s'), h('th', {}, 'set point °C'),
          h('th', {}, `ramp °C/min (0: step${lim ? `; ≤ ${lim.max_ramp_C_per_min}` : ''})`), h('th', {}, ''))),
        stepsBody) : h('p', { class: 'hint' }, 'No set-point steps: the chamber holds the set point for the whole program.'),
      h('div', { class: 'field-error', id: 'chamber-error', dataset: { field: 'chamber' } }),
      h('button', { type: 'button', id: 'add-step', onclick: () => {
        const last = ch.steps[ch.steps.length - 1];
        ch.steps.push({ at_s: last ? last.at_s + 600 : 600, setpoint_C: (last?.setpoint_C ?? ch.setpoint_C ?? 25) + 10, ramp_C_per_min: 1 });
        renderChamber();
        changed();
      } }, 'Add set-point step'));
  }

  // sim_faults (docs/api.md): what the simulated bench does wrong, and when, to see the
  // suspenders work (a chamber offset suspends the run; it resumes by itself when it clears).
  function renderFaults() {
    const faults = draft.campaign.sim_faults || (draft.campaign.sim_faults = []);
    clear(faultsBox);
    const body = h('tbody', { id: 'faults' });
    faults.forEach((fault, i) => {
      const numField = (key, label, required) => {
        const el = input(`fault-${i}-${key}`, `sim_faults[${i}].${key}`, fault[key], { type: 'text', inputmode: 'decimal', class: 'short', 'aria-label': `fault ${i + 1} ${label}` });
        el.addEventListener('input', () => {
          const r = parseNumber(el.value);
          let err = r.error || (r.empty && required ? 'required' : null);
          if (!err && !r.empty && key !== 'offset_C' && r.value < 0) err = 'must not be negative';
          if (!err) { if (r.empty) delete fault[key]; else fault[key] = r.value; }
          setError(el, err);
          changed();
        });
        return h('label', { class: 'param' }, h('span', {}, label), el, h('div', { class: 'field-error', id: `${el.id}-error` }));
      };
      const kind = h('select', { id: `fault-${i}-kind`, 'aria-label': `fault ${i + 1} kind` },
        ...FAULT_KINDS.map((k) => h('option', { value: k, selected: fault.kind === k }, k)));
      kind.addEventListener('change', () => {
        faults[i] = { kind: kind.value, at_s: fault.at_s, duration_s: fault.duration_s, ...FAULT_EXTRA[kind.value] };
        dropErrors(`fault-${i}-`);
        renderFaults();
        changed();
      });
      const extra = [];
      if (fault.kind === 'chamber_offset') extra.push(numField('offset_C', 'offset °C', true));
      if (fault.kind === 'imu_corrupt' || fault.kind === 'imu_drop') extra.push(numField('frames', 'frames', true));
      if (fault.kind === 'disconnect') {
        const dev = h('select', { id: `fault-${i}-device`, 'aria-label': `fault ${i + 1} device` },
          ...['table', 'chamber', 'imu'].map((d) => h('option', { value: d, selected: fault.device === d }, d)));
        dev.addEventListener('change', () => { fault.device = dev.value; changed(); });
        extra.push(h('label', { class: 'param' }, h('span', {}, 'device'), dev));
      }
      body.append(h('tr', { dataset: { field: `sim_faults[${i}]` } },
        h('td', { class: 'num' }, i + 1), h('td', {}, kind),
        h('td', {}, h('div', { class: 'params' }, numField('at_s', 'at program time s', true), numField('duration_s', 'duration s', false), ...extra)),
        h('td', {}, h('button', { type: 'button', class: 'link', 'aria-label': `remove fault ${i + 1}`, onclick: () => {
          faults.splice(i, 1);
          dropErrors('fault-');
          renderFaults();
          changed();
        } }, 'remove'))));
    });
    faultsBox.append(
      faults.length ? h('table', { class: 'steps faults' }, body) : h('p', { class: 'hint' }, 'None: the simulated bench behaves. Faults apply to simulated devices only.'),
      h('button', { type: 'button', id: 'add-fault', onclick: () => {
        faults.push({ kind: 'chamber_offset', at_s: 60, duration_s: 20, offset_C: 6 });
        renderFaults();
        changed();
      } }, 'Add fault'));
  }

  function renderSegments() {
    clear(segmentsBody);
    draft.program.segments.forEach((seg, i) => segmentsBody.append(segmentRow(seg, i)));
  }

  function segmentRow(seg, i) {
    const type = seg.type;
    const fields = SEGMENT_TYPES[type] || [];
    const nameInput = titled(h('input', { type: 'text', id: `seg-${i}-name`, value: seg.name || '', class: 'seg-name', 'aria-label': `segment ${i + 1} name` }));
    nameInput.addEventListener('input', () => {
      const v = nameInput.value.trim();
      const dup = v && draft.program.segments.some((s, j) => j !== i && s.name === v);
      const err = !v ? 'needs a name' : dup ? 'another segment has this name' : null;
      if (!err) seg.name = v;
      setError(nameInput, err);
      modified();
    });
    const typeSelect = h('select', { id: `seg-${i}-type`, 'aria-label': `segment ${i + 1} type` },
      ...Object.keys(SEGMENT_TYPES).map((t) => h('option', { value: t, selected: t === type }, t)),
      SEGMENT_TYPES[type] ? null : h('option', { value: type, selected: true }, type));
    typeSelect.addEventListener('change', () => {
      const keep = { type: typeSelect.value, name: seg.name };
      draft.program.segments[i] = { ...keep, ...structuredClone(NEW_SEGMENT[typeSelect.value] || {}) };
      dropErrors(`seg-${i}-`);
      renderSegments();
      modified();
    });
    const params = h('div', { class: 'params' });
    for (const f of fields) {
      const id = `seg-${i}-${f.key}`;
      let control;
      if (f.kind === 'axis') {
        control = h('select', { id, 'aria-label': `segment ${i + 1} ${f.label}` },
          ...AXIS_NAMES.map((a) => h('option', { value: a, selected: seg[f.key] === a }, a)));
        if (!seg[f.key]) seg[f.key] = 'outer';
        control.addEventListener('change', () => { seg[f.key] = control.value; modified(); });
      } else {
        const text = formatValue(f, seg[f.key]);
        // A list of positions: one per line in a box that shows them all (twelve positions in
        // one line of text were cut off).
        control = f.kind === 'vec3list'
          ? h('textarea', { id, 'aria-label': `segment ${i + 1} ${f.label}`, class: 'positions', spellcheck: 'false',
            rows: String(Math.min(12, Math.max(2, (seg[f.key] || []).length))), value: text })
          : titled(h('input', { type: 'text', id, value: text, 'aria-label': `segment ${i + 1} ${f.label}`,
            class: f.kind === 'number' ? 'short' : '', spellcheck: 'false' }));
        control.addEventListener('input', () => {
          const r = parseField(f, control.value);
          let err = r.error || null;
          if (r.empty && f.required) err = 'required';
          if (!err) {
            if (r.empty) delete seg[f.key]; else seg[f.key] = r.value;
          }
          if (type === 'rate' && !err) {
            const either = seg.revolutions !== undefined || seg.duration_s !== undefined;
            setError(params, either ? null : 'give revolutions or a duration', `seg-${i}-params-error`);
          }
          setError(control, err);
          modified();
        });
      }
      params.append(h('label', { class: 'param' }, h('span', {}, f.label), control));
    }
    const known = new Set(['type', 'name', ...fields.map((f) => f.key)]);
    const others = Object.keys(seg).filter((k) => !known.has(k));
    if (others.length) params.append(h('span', { class: 'muted', title: 'kept as they are' }, others.map((k) => `${k}: ${JSON.stringify(seg[k])}`).join(', ')));
    const count = type === 'positions' || type === 'tilts' ? ` (${(seg.positions_deg || []).length} positions)` : '';
    const move = (d) => {
      const j = i + d;
      if (j < 0 || j >= draft.program.segments.length) return;
      const s = draft.program.segments;
      [s[i], s[j]] = [s[j], s[i]];
      fieldErrors = new Map([...fieldErrors].filter(([k]) => !k.startsWith('seg-')));
      renderSegments();
      modified();
    };
    return h('tr', { id: `segment-${i}`, dataset: { index: i, name: seg.name || '' }, class: 'segment' },
      h('td', { class: 'num' }, i + 1),
      h('td', {}, nameInput, h('div', { class: 'field-error', id: `seg-${i}-name-error` })),
      h('td', {}, typeSelect),
      h('td', {}, params, count ? h('span', { class: 'muted' }, count) : null,
        h('div', { class: 'field-error', id: `seg-${i}-params-error` }),
        ...fields.map((f) => h('div', { class: 'field-error', id: `seg-${i}-${f.key}-error` })),
        h('ul', { class: 'segment-problems', id: `seg-${i}-problems` })),
      h('td', { class: 'num seg-time', id: `seg-${i}-time` }, ''),
      h('td', { class: 'row-actions' },
        h('button', { type: 'button', class: 'icon', title: 'move up', 'aria-label': `move segment ${i + 1} up`, onclick: () => move(-1) }, '↑'),
        h('button', { type: 'button', class: 'icon', title: 'move down', 'aria-label': `move segment ${i + 1} down`, onclick: () => move(1) }, '↓'),
        h('button', { type: 'button', class: 'icon copy', title: 'duplicate', 'aria-label': `duplicate segment ${i + 1}`, onclick: () => {
          const copy = structuredClone(seg);
          copy.name = uniqueName(`${seg.name || type}-copy`);
          draft.program.segments.splice(i + 1, 0, copy);
          fieldErrors = new Map([...fieldErrors].filter(([k]) => !k.startsWith('seg-')));
          renderSegments();
          modified();
        } }, 'copy'),
        h('button', { type: 'button', class: 'icon danger-text', title: 'delete', 'aria-label': `delete segment ${i + 1}`, onclick: () => {
          draft.program.segments.splice(i, 1);
          fieldErrors = new Map([...fieldErrors].filter(([k]) => !k.startsWith('seg-')));
          renderSegments();
          modified();
        } }, '✕')));
  }

  function uniqueName(base) {
    let name = base, n = 2;
    while (draft.program.segments.some((s) => s.name === name)) name = `${base}-${n++}`;
    return name;
  }

  function addSegment(type) {
    draft.program.segments.push({ type, name: uniqueName(type), ...structuredClone(NEW_SEGMENT[type]) });
    renderSegments();
    modified();
    segmentsBody.lastElementChild?.querySelector('input')?.focus();
  }

  // ---- state changes ----

  function setError(el, message, id = `${el.id}-error`) {
    const box = root.querySelector(`#${CSS.escape(id)}`);
    if (box) box.textContent = message || '';
    if (el.setAttribute) el.setAttribute('aria-invalid', message ? 'true' : 'false');
    // The side panel lists these away from their fields: each names its field as the form does.
    const name = fieldName(el, id);
    if (message) fieldErrors.set(id, name ? `${name}: ${message}` : message); else fieldErrors.delete(id);
  }

  // The name the form gives a field: its label, or "segment 3 rate (deg/s)" in the program table.
  function fieldName(el, id) {
    const aria = el.getAttribute?.('aria-label');
    if (aria) return aria;
    const label = el.id && root.querySelector(`label[for="${CSS.escape(el.id)}"]`);
    if (label) return label.textContent.trim();
    const segment = /^seg-(\d+)-/.exec(id);
    return segment ? `segment ${Number(segment[1]) + 1}` : null;
  }

  function dropErrors(prefix) {
    fieldErrors = new Map([...fieldErrors].filter(([k]) => !k.startsWith(prefix)));
  }

  function setCampaign(key, value, error, el) {
    if (!error) {
      if (value === undefined) delete draft.campaign[key]; else draft.campaign[key] = value;
    }
    setError(el, error);
    changed();
  }

  function setChamber(key, value, error, el) {
    if (!error) {
      if (value === undefined) delete draft.campaign.chamber[key]; else draft.campaign.chamber[key] = value;
    }
    setError(el, error);
    changed();
  }

  // Edited means different from the built-in program: an edit undone by hand is no edit, and the
  // campaign names the built-in program again.
  function modified() {
    const template = programs.find((x) => x.name === draft.template);
    draft.modified = !template || canonical(draft.program) !== canonical(template.program);
    const mark = templateInfo.querySelector('.modified');
    if (draft.modified && !mark) templateInfo.append(h('strong', { class: 'modified' }, ' Edited: sent as an inline program.'));
    if (!draft.modified) mark?.remove();
    changed();
  }

  /** The campaign JSON to send (docs/api.md, "Campaign JSON"). */
  function body() {
    const c = draft.campaign;
    const out = { name: (c.name || '').trim() };
    out.program = draft.modified || !draft.template ? draft.program : draft.template;
    if (Array.isArray(c.estimators)) out.estimators = c.estimators;
    for (const k of ['rate_hz', 'time_scale', 'seed']) if (c[k] !== undefined) out[k] = c[k];
    if (c.truth !== undefined) out.truth = c.truth;
    // The unit: its serial and whichever of the other fields are filled in.
    const unit = c.imu || {};
    if ((unit.serial || '').trim()) {
      out.imu = { serial: unit.serial.trim() };
      for (const k of ['part_number', 'firmware', 'customer', 'notes']) if ((unit[k] || '').trim()) out.imu[k] = unit[k].trim();
    }
    if (c.sim_faults?.length) out.sim_faults = c.sim_faults;
    const ch = c.chamber || {};
    if (ch.setpoint_C !== undefined) {
      out.chamber = { setpoint_C: ch.setpoint_C };
      if (ch.tolerance_C !== undefined) out.chamber.tolerance_C = ch.tolerance_C;
      if (ch.steps?.length) out.chamber.steps = ch.steps;
    } else if (ch.steps?.length) {
      out.chamber = { steps: ch.steps, ...(ch.tolerance_C !== undefined ? { tolerance_C: ch.tolerance_C } : {}) };
    }
    return out;
  }

  function clientProblems() {
    const list = [...fieldErrors.values()];
    if (!draft.program.segments.length) list.push('The program has no segments.');
    if (!(draft.campaign.name || '').trim() && !fieldErrors.has('c-name-error')) list.push('A campaign needs a name.');
    return list;
  }

  function changed(save = true) {
    if (save) saveDraft();
    preview.textContent = JSON.stringify(body(), null, 1).slice(0, 20000);
    serverMessage.textContent = '';
    clearTimeout(validateTimer);
    clearTimeout(planTimer);
    planSeq++;  // a prediction under way is for the previous program
    // The prediction on show is the previous campaign's: marked so at once (greyed, its status
    // saying so), and taken away if the edit makes the campaign invalid (renderVerdict).
    if (lastPrediction) {
      planStatus.dataset.state = 'checking';
      planStatus.textContent = 'Edited: predicted again once the campaign is valid.';
      planTable.dataset.stale = 'true';
    }
    const local = clientProblems();
    if (local.length) {
      validation = { state: 'local', problems: local, duration_s: null, segments: [] };
      renderVerdict();
      return;
    }
    validation = { ...validation, state: 'checking' };
    renderVerdict();
    validateTimer = setTimeout(validate, 350);
  }

  async function validate() {
    const seq = ++validateSeq;
    try {
      const r = await post('/api/campaigns/validate', body());
      if (seq !== validateSeq || destroyed) return;  // a newer edit is being checked
      validation = { state: r.valid ? 'valid' : 'invalid', problems: r.problems || [], duration_s: r.duration_s, segments: r.segments || [] };
      if (r.valid) schedulePlan();
    } catch (e) {
      if (seq !== validateSeq || destroyed) return;
      validation = { state: 'error', problems: e instanceof ApiError ? (e.problems.length ? e.problems : [e.message]) : [String(e)], duration_s: null, segments: [] };
    }
    renderVerdict();
  }

  // ---- the prediction ----

  function targetId(group) { return `target-${group.replace(/\./g, '-')}`; }

  function loadPlanSettings() {
    try {
      const saved = JSON.parse(localStorage.getItem(PLAN_KEY) || 'null');
      if (saved && typeof saved === 'object')
        return { ...planDefaults(), ...saved, targets: { ...seedTargets(), ...(saved.targets || {}) } };
    } catch { /* unreadable: the defaults */ }
    return planDefaults();
  }

  // The noise inputs change the prediction (asked again); the targets only its verdicts.
  function planInputChanged() {
    const read = (id) => parseNumber(root.querySelector(`#${id}`).value);
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
    if (noiseChanged && validation.state === 'valid') schedulePlan();
    else if (lastPrediction) renderPrediction(lastPrediction);
  }

  function schedulePlan() {
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
        if (seq !== planSeq || destroyed) return false;  // edited since: this one is no longer wanted
        planStatus.textContent = `Predicting… ${Math.round(100 * (p.progress || 0))} %`;
        return true;
      } });
      if (seq !== planSeq || destroyed) return;
      lastPrediction = r;
      renderPrediction(r);
    } catch (e) {
      if (seq !== planSeq || destroyed) return;
      clearPrediction('error', `No prediction: ${e.message}`);
    }
  }

  function clearPrediction(state, text) {
    lastPrediction = null;
    clear(planBody);
    clear(planWeak);
    clear(planBench);
    delete planTable.dataset.stale;
    planStatus.dataset.state = state;
    planStatus.textContent = text;
  }

  function renderPrediction(p) {
    const rows = predictionRows(p, planSettings.targets);
    const s = summary(rows);
    planStatus.dataset.state = s.judged && s.met === s.judged ? 'valid' : 'invalid';
    delete planTable.dataset.stale;
    planStatus.textContent = `${duration(p.duration_s)} of program at ${rateText(p.rate_hz)}: ${s.met} of ${s.judged} targets met` +
      (s.worst && !s.worst.meets ? `; worst ${s.worst.name} at ${num(s.worst.ratio, 2)}× its target.` : '.');
    clear(planBody);
    const dominant = { direct: dominantSources(p, 'direct'), navigation: dominantSources(p, 'navigation') };
    for (const row of rows) {
      // The dominant source of the stage that predicts the row (stage 1's or stage 3's budget).
      const d = dominant[row.stage]?.get(row.name) ?? null;
      // Four columns fit the side panel: the stage under the name, the name breakable after each dot.
      planBody.append(h('tr', { class: row.meets === false ? 'misses' : row.meets ? 'meets' : '', dataset: { name: row.name, stage: row.stage } },
        h('td', {}, row.name.split('.').flatMap((p, i) => (i ? [h('wbr'), `.${p}`] : [p])), h('span', { class: 'plan-stage' }, row.stage)),
        h('td', { class: 'num' }, num(row.sigma, 3)),
        h('td', { class: 'num' }, row.target === null ? '' : num(row.target, 3)),
        h('td', { class: 'dominant' }, d ? `${sourceName(d.source)} (${Math.round(100 * d.share)} %)` : '')));
    }
    clear(planBench);
    renderBench(benchRequirements(p, 'direct'), 'stage 1');
    renderBench(benchRequirements(p, 'navigation'), 'stage 3');
    clear(planWeak);
    for (const w of p.weak || [])
      planWeak.append(h('li', { class: 'problem' }, `${w.coefficient} (${w.stage}): ${w.why}; needs ${w.fix}`));
    // The nonlinear terms the program does not determine: taken from the model, said as such.
    for (const w of p.from_model || [])
      planWeak.append(h('li', { class: 'from-model', dataset: { coefficient: w.coefficient } }, `${w.coefficient}: ${w.why}; to determine it, ${w.fix}`));
    // The tumble's terms determined less well than the unit needs (issue 34).
    for (const w of p.short_of_needs || [])
      planWeak.append(h('li', { class: 'problem short-of-needs', dataset: { coefficient: w.coefficient } }, `${w.coefficient} (${w.stage}): ${w.why}; needs ${w.fix}`));
  }

  // The campaign's own frame rate, and the one the prediction simulated when that differs.
  // imucald simulates at 20 Hz unless told (docs/api.md): a 6 h program's prediction took 45 s at
  // 20 Hz on the 2-core test machine and grows with the rate, while the σ it predicts do not
  // (the sensors' white noise is a density: its effect on a static's mean depends on the time,
  // not the frames; \`imucal plan\` on direct-short gives the same σ within 0.5 % at 20 and 100 Hz).
  function rateText(simulatedHz) {
    const own = draft.campaign.rate_hz;
    const hz = (v) => `${Number(v.toPrecision(6))} Hz`;  // 50 Hz as typed, not "50.0 Hz"
    if (!(own > 0) || own === simulatedHz) return hz(simulatedHz);
    return `the campaign's ${hz(own)} (simulated at ${hz(simulatedHz)}: white noise's σ does not depend on the frame rate)`;
  }

  // The bench for a stage's limits: per source its 1-sigma and the largest that still meets them.
  function renderBench(req, stageName) {
    if (!req) return;
    const text = (b) => (b.maxSigma === null && b.maxFactor === null ? 'no limit'
      : b.maxFactor === 0 ? `none suffices (${b.limiting})` : `≤ ${num(b.maxSigma ?? b.maxFactor, 3)} (${b.limiting})`);
    const first = stageName === 'stage 1';
    planBench.append(h('h3', {}, `Bench for ${stageName}'s limits`),
      req.sources.length === 0
        ? h('p', { class: 'hint' }, 'No table certificate in imucald\'s configuration (table): the table\'s errors are not in the budget.')
        : h('table', { class: 'plan-table', id: first ? 'plan-bench-table' : 'plan-bench-table-stage3' },
          h('thead', {}, h('tr', {}, h('th', {}, 'Source'), h('th', { class: 'num' }, '1σ'), h('th', {}, 'Alone'), h('th', {}, 'With the others'))),
          h('tbody', {}, ...req.sources.map((r) => h('tr', { dataset: { source: r.source } },
            h('td', {}, sourceName(r.source)), h('td', { class: 'num' }, num(r.sigma, 3)), h('td', {}, text(r.alone)), h('td', {}, text(r.withOthers)))))),
      req.wholeTable ? h('p', { class: 'hint', id: first ? 'plan-whole-table' : 'plan-whole-table-stage3' },
        `The whole table certificate scaled together (no g error): ${req.wholeTable.maxFactor === null ? 'no limit' : `at most ${num(req.wholeTable.maxFactor, 3)}× (${req.wholeTable.limiting})`}.`) : null,
    );
  }

  function renderVerdict() {
    const v = validation;
    verdict.dataset.state = v.state;
    const scale = draft.campaign.time_scale;
    const wall = v.duration_s && scale > 0 ? v.duration_s / scale : null;
    const texts = {
      idle: 'Not checked yet.',
      local: 'Fix the marked fields; nothing is sent until they are valid.',
      checking: 'Checking with imucald…',
      valid: `Valid: ${v.segments.length} segments, ${duration(v.duration_s)} of program${wall ? `, about ${duration(wall)} at ×${num(scale, 3)}` : ''}.`,
      invalid: `Refused: ${v.problems.length} problem${v.problems.length === 1 ? '' : 's'}${v.duration_s ? `; program ${duration(v.duration_s)}` : ''}.`,
      error: 'The check failed.',
    };
    verdict.textContent = texts[v.state] || v.state;
    if ((v.state === 'local' || v.state === 'invalid') && (lastPrediction || planTable.dataset.stale))
      clearPrediction('idle', 'No prediction while the campaign is invalid: predicted again once it is valid.');
    // Inline: each problem beside its segment or field; the rest in the side panel.
    for (const ul of root.querySelectorAll('.segment-problems')) clear(ul);
    for (const tr of root.querySelectorAll('tr.segment')) tr.classList.remove('has-problems');
    for (const el of root.querySelectorAll('[data-field]')) el.classList.remove('has-problems');
    for (const el of root.querySelectorAll('.server-field-problem')) el.remove();
    clear(problemsList);
    if (v.state === 'local') {
      for (const p of v.problems) problemsList.append(h('li', {}, p));
    } else if (v.state === 'invalid' || v.state === 'error') {
      const mapped = mapProblems(v.problems, draft.program.segments);
      for (const [i, list] of mapped.bySegment) {
        const ul = root.querySelector(`#seg-${i}-problems`);
        root.querySelector(`#segment-${i}`)?.classList.add('has-problems');
        for (const p of compress(list)) ul?.append(h('li', { class: 'problem' }, p.replace(/^campaign\.program: /, '')));
      }
      for (const [path, list] of mapped.byField) {
        const host = root.querySelector(`[data-field="${CSS.escape(path)}"]`) || root.querySelector(`[data-field="${CSS.escape(path.split(/[.[]/)[0])}"]`);
        if (!host) { mapped.general.push(...list); continue; }
        host.classList.add('has-problems');
        host.append(h('div', { class: 'server-field-problem problem' }, list.map(problemForPeople).join('; ')));
      }
      for (const p of compress(v.problems)) problemsList.append(h('li', { class: 'problem' }, problemForPeople(p)));
    }
    renderTimes(v.segments);
    updateRoleUi();
  }

  // Program time of each source segment, from the compiled segments the daemon returned.
  function renderTimes(compiled) {
    draft.program.segments.forEach((s, i) => {
      const cell = root.querySelector(`#seg-${i}-time`);
      if (cell) cell.textContent = '';
    });
    const spans = new Map();
    for (const c of compiled) {
      const i = sourceIndex(c.name, draft.program.segments);
      if (i < 0) continue;
      const s = spans.get(i) || { t0: Infinity, t1: -Infinity };
      s.t0 = Math.min(s.t0, c.t0_s);
      s.t1 = Math.max(s.t1, c.t1_s);
      spans.set(i, s);
    }
    for (const [i, s] of spans) {
      const cell = root.querySelector(`#seg-${i}-time`);
      if (cell) cell.textContent = `${s.t0.toFixed(0)}–${s.t1.toFixed(0)} s`;
    }
  }

  function updateRoleUi() {
    const operator = isOperator();
    // A campaign imucald's check refused would only be refused again (422): fix it first.
    const blocked = validation.state === 'local' || validation.state === 'checking' || validation.state === 'invalid';
    for (const b of [createButton, startButton]) {
      b.disabled = !operator || blocked;
      b.title = !operator ? 'operator role required'
        : validation.state === 'invalid' ? 'imucald refused this campaign: fix the problems listed'
          : blocked ? 'wait for the check, or fix the marked fields' : '';
    }
    viewerNote.hidden = operator;
  }

  // ---- create / start ----

  async function submit(andStart) {
    serverMessage.textContent = '';
    const local = clientProblems();
    if (local.length) {
      serverMessage.textContent = 'Fix the marked fields first.';
      return;
    }
    const b = body();
    if (andStart) {
      const scale = b.time_scale;
      const d = validation.duration_s;
      const answer = await confirmDialog({
        title: `Create and start "${b.name}"?`,
        body: [`The table will move as soon as the devices are free: ${typeof b.program === 'string' ? `program "${b.program}"` : `an edited program (${draft.program.segments.length} segments)`}, ${duration(d)} of program time${scale > 0 ? ` (about ${duration(d / scale)} at ×${scale})` : ''}.`,
          `Chamber: ${b.chamber?.setpoint_C !== undefined ? `${b.chamber.setpoint_C} °C ± ${b.chamber.tolerance_C ?? '?'} °C` : 'the safe set point'}${b.chamber?.steps?.length ? `, then ${b.chamber.steps.length} set-point step(s)` : ''}.`,
          'Make sure nobody is near the table and the IMU is mounted and cabled.'],
        confirmLabel: 'Start — the table will move', reason: false });
      if (!answer.ok) return;
    }
    createButton.disabled = startButton.disabled = true;
    try {
      const created = await post('/api/campaigns', b);
      sessionStorage.removeItem(DRAFT_KEY);
      if (andStart) {
        // (Reference equipment past its due date: the operator is asked for the override's reason.)
        const started = await startCampaign(created.id, '').catch(() => null);
        if (!started) {
          ctx.navigate(`#/campaigns/${created.id}`);
          return;
        }
        // Another campaign on the bench: this one waits in the queue, and its own page says so
        // (the live view would show the other run).
        const status = await get('/api/status').catch(() => null);
        const other = status?.active && status.active.id !== created.id;
        ctx.navigate(other ? `#/campaigns/${created.id}` : '#/live');
      } else {
        ctx.navigate(`#/campaigns/${created.id}`);
      }
    } catch (e) {
      // 400/422: every problem, inline and in the panel, just as from the check.
      if (e instanceof ApiError && e.problems.length) {
        validation = { state: 'invalid', problems: e.problems, duration_s: validation.duration_s, segments: validation.segments };
        renderVerdict();
      }
      serverMessage.textContent = `imucald refused the campaign: ${e.message}`;
      updateRoleUi();
    }
  }

  return () => {
    destroyed = true;
    clearTimeout(validateTimer);
    clearTimeout(planTimer);
    offSession();
  };
}
