// The builder's draft: a built-in program with the campaign around it, kept in sessionStorage so
// that a reload or a sign-in on the way loses nothing; the campaign JSON it sends; and what the
// page itself finds wrong with it before anything is sent.
import { defaultTruth } from '../../truths.mjs';

const DRAFT_KEY = 'imucal.builder.draft';

export function readDraft() {
  try {
    const d = JSON.parse(sessionStorage.getItem(DRAFT_KEY) || 'null');
    return d && d.campaign && d.program && Array.isArray(d.program.segments) ? d : null;
  } catch {
    return null;
  }
}

export function saveDraft(draft) {
  try { sessionStorage.setItem(DRAFT_KEY, JSON.stringify(draft)); } catch { /* private mode: no draft */ }
}

export function forgetDraft() {
  sessionStorage.removeItem(DRAFT_KEY);
}

/** A fresh draft of built-in program p (GET /api/programs) under imucald's limits. */
export function templateDraft(p, limits) {
  const known = limits?.campaign?.estimators || [];
  return {
    template: p.name,
    modified: false,
    campaign: {
      name: `${p.name} check`,
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
}

/** The campaign JSON to send (docs/api.md, "Campaign JSON"). */
export function campaignBody(draft) {
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

/** What the page finds wrong before anything is sent: the fields' problems and an empty program. */
export function clientProblems(draft, fieldErrors) {
  const list = [...fieldErrors.values()];
  if (!draft.program.segments.length) list.push('The program has no segments.');
  if (!(draft.campaign.name || '').trim() && !fieldErrors.has('c-name-error')) list.push('A campaign needs a name.');
  return list;
}
