// What a calibration certificate says, as data: its coefficient rows (names, units, standard and
// expanded uncertainty, "not determined", the verdict per coefficient) and its statements (the
// verdict, a partial run, the reference equipment, the site's gravity, the conventions). Pure
// functions of the daemon's replies, without the DOM, so that Node tests them
// (tests/browser/unit.test.mjs); certificate.mjs only lays them out.
import { coefficientRows, coefficientName, determined, groupOf } from './coefficients.mjs';
import { num, dateTime, timeOfDay, FINAL_STATES } from './format.mjs';

/** The coverage factor of the expanded uncertainty: U = k u. */
export const COVERAGE_K = 2;

export const NOT_DETERMINED = 'not determined';

/** A limit of the verdict in words: "|value| ≤ 0.05; u ≤ 0.002" ('' when it has none). */
export function limitText(c) {
  const parts = [];
  if (typeof c?.limit_value === 'number') parts.push(`|value| ≤ ${num(c.limit_value, 4)}`);
  if (typeof c?.limit_sigma === 'number') parts.push(`u ≤ ${num(c.limit_sigma, 4)}`);
  return parts.join('; ');
}

/**
 * The rows of the certificate's coefficient table from the model (with its sigma section) and
 * the run's verdict (GET /api/campaigns/{id}: verdict; null when there are no limits):
 *   {key, name, unit, determined, value, u, U, limit, pass, reason}
 * value, u (k = 1) and U (k = 2) are null where the run did not determine them, which the page
 * prints as "not determined". A group the run determined nothing of (a direct run's delays and
 * proof-mass offsets) becomes one row {collapsed: true, key: 'gyro.delay_us', name: 'Gyro
 * delay', ...}, unless a limit applies to one of its coefficients. limit, pass and reason come
 * from the verdict (pass null: no limit on this coefficient).
 */
export function certificateRows(model, verdict) {
  const judged = new Map((verdict?.coefficients || []).map((c) => [c.key, c]));
  const rows = [];
  for (const r of coefficientRows(model, null)) {
    const key = r.name;
    const det = determined(key, r.estimate, r.sigma);
    const u = det && typeof r.sigma === 'number' && r.sigma > 0 ? r.sigma : null;
    rows.push(row(key, r.unit, det ? r.estimate : null, u, judged.get(key)));
    judged.delete(key);
  }
  // A limit on a coefficient the model does not carry (missing keys read as zero): still shown.
  for (const c of judged.values()) rows.push(row(c.key, '', null, null, c));

  const out = [];
  const done = new Set();
  for (const r of rows) {
    const group = groupOf(r.key);
    if (!group) {
      out.push(r);
      continue;
    }
    if (done.has(group.key)) continue;
    const members = rows.filter((m) => groupOf(m.key) === group);
    if (members.some((m) => m.determined || m.pass !== null)) {
      out.push(...members);
    } else {
      out.push({ collapsed: true, key: group.key, name: group.title, unit: r.unit, determined: false,
        value: null, u: null, U: null, limit: '', pass: null, reason: '', count: members.length });
    }
    done.add(group.key);
  }
  return out;
}

function row(key, unit, value, u, judged) {
  return {
    key, name: coefficientName(key), unit, determined: value !== null, value, u,
    U: u === null ? null : COVERAGE_K * u,
    limit: judged ? limitText(judged) : '',
    pass: judged ? Boolean(judged.pass) : null,
    reason: judged?.reason || '',
  };
}

/**
 * A row's numbers as printed, rounded as a calibration certificate rounds them (GUM 7.2.6): the
 * uncertainties to two significant digits, the estimate to the same decimal place as u. Small
 * numbers in exponent form, so that no column needs more than six decimals:
 *   {value: '-3.75e-6', u: '1.2e-5', U: '2.4e-5'}; null for what was not determined.
 * A term without an uncertainty (the noise terms) keeps three significant digits.
 */
export function roundedNumbers(r) {
  if (r.value === null) return { value: null, u: null, U: null };
  if (r.u === null) return { value: num(r.value, 3), u: null, U: null };
  const place = Math.floor(Math.log10(r.u)) - 1; // u's second significant digit
  const exponent = place < -6; // the row's three numbers in one form
  return { value: atPlace(r.value, place, exponent), u: atPlace(r.u, place, exponent, true),
    U: atPlace(r.U, Math.floor(Math.log10(r.U)) - 1, exponent, true) };
}

// `v` rounded at the decimal place 10^place, in exponent form or not; `twoDigits`: v is an
// uncertainty (two significant digits, always).
function atPlace(v, place, exponent, twoDigits = false) {
  if (!exponent) return (Math.round(v / 10 ** place) * 10 ** place).toFixed(Math.max(0, -place));
  if (twoDigits) return v.toExponential(1);
  const mag = v === 0 ? place : Math.floor(Math.log10(Math.abs(v)));
  // At least as many digits as the place asks for, and never fewer than u's own two.
  const e = Math.max(mag, place + 1);
  return `${(v / 10 ** e).toFixed(e - place)}e${e}`;
}

/**
 * The verdict for the title block: {status: 'PASS' | 'FAIL' | null, text}. `partNumber` is the
 * campaign's unit's (the verdict is null without limits for it, or without a part number).
 */
export function verdictStatement(verdict, partNumber) {
  if (!verdict) {
    return { status: null, text: partNumber ? `No acceptance limits for part number ${partNumber}`
      : 'No part number given: not judged against acceptance limits' };
  }
  const source = verdict.limits ? ` (limits: ${verdict.limits})` : '';
  if (verdict.pass) return { status: 'PASS', text: `Meets the acceptance limits of part number ${verdict.part_number}${source}` };
  const n = verdict.failures ?? (verdict.coefficients || []).filter((c) => !c.pass).length;
  return { status: 'FAIL', text: `${n} coefficient${n === 1 ? '' : 's'} outside the acceptance limits of part number ${verdict.part_number}${source}` };
}

/**
 * Why a run is partial, for the title block: null for a complete run (or one not ended), else
 * "stopped at 59 % of the program (stop by alice at 14:03)", with the operator's acceptance.
 */
export function partialStatement(d) {
  if (!FINAL_STATES.has(d.state) || d.complete) return null;
  const pct = `${Math.round(100 * (d.progress || 0))} % of the program`;
  const ending = [...(d.transitions || [])].reverse().find((t) => t.to === 'stopping' || t.to === 'aborting');
  let text;
  if (d.state === 'failed') text = `failed at ${pct}${d.error ? `: ${d.error}` : ''}`;
  else if (ending) text = `${ending.to === 'stopping' ? 'stopped' : 'aborted'} at ${pct} (${ending.reason}, ${timeOfDay(ending.t)})`;
  else text = `${d.state === 'aborted' ? 'aborted' : 'ended'} at ${pct}`;
  if (d.accepted) text += `; accepted as a calibration by ${d.accepted.by}: ${d.accepted.reason}`;
  return text;
}

/**
 * The override of overdue reference equipment the run was started under, as one statement, or
 * null when it was started without one. From the certificate's campaign.override_overdue
 * (imucald's record of the start: by, at, reason, and `text`, imucald's own words for the
 * instruments, which the page does not compose again):
 * "Started by alice (2026-11-28 09:14:02, local time) although the rate table (...) was due for
 * calibration on 2020-01-31; reason given: customer deadline".
 */
export function overrideStatement(campaign) {
  const o = campaign?.override_overdue;
  if (!o) return null;
  return `Started by ${o.by} (${dateTime(o.at)}, local time) although ${o.text}; reason given: ${o.reason}`;
}

/**
 * The reference equipment as lines [{role, text, overdue, missing}] from the certificate reply
 * (GET /api/campaigns/{id}/certificate): the rate table and the chamber (simulated devices are said
 * to be simulated), then the survey of the site's g. Each with its certificate, its uncertainty
 * and its due date, OVERDUE when it was due before the run ended (imucald's judgement, stated in
 * the certificate). What a certificate issued before a field existed does not state (the
 * uncertainties, the gravity survey) is left out, not shown as missing: it is printed as issued.
 */
export function equipmentLines(cert) {
  const equipment = cert.reference_equipment || {};
  const lines = [];
  if (cert.simulated) {
    lines.push({ role: 'Reference equipment', overdue: false, missing: false,
      text: `Simulated three-axis rate table and chamber (imucald devices "${cert.devices}"): no physical reference equipment.` });
  } else {
    for (const [key, role] of [['table', 'Rate table'], ['chamber', 'Climatic chamber']]) {
      const i = equipment[key];
      if (!i) {
        lines.push({ role, overdue: false, missing: true, text: `not stated in the configuration (reference_equipment.${key})` });
        continue;
      }
      const text = `${i.make} ${i.model}, serial number ${i.serial}; calibration due ${i.calibration_due}` +
        `${i.calibration_certificate ? ` (its certificate ${i.calibration_certificate})` : ''}` +
        `${'uncertainty' in i ? `; uncertainty ${i.uncertainty || 'not stated'}` : ''}` +
        `${i.overdue ? ' — OVERDUE: its calibration had run out when this run was made' : ''}`;
      lines.push({ role, overdue: Boolean(i.overdue), missing: false, text });
    }
  }
  if ('gravity' in equipment) lines.push(gravitySurveyLine(equipment.gravity, cert.gravity));
  return lines;
}

function gravitySurveyLine(survey, gravity) {
  const role = 'Gravity survey';
  if (!survey) {
    return gravity?.source === 'normal_gravity'
      ? { role, overdue: false, missing: false, text: 'none: the site\'s g is computed (WGS-84 normal gravity), not measured' }
      : { role, overdue: false, missing: true, text: 'not stated in the configuration (reference_equipment.gravity)' };
  }
  const text = `surveyed by ${survey.surveyed_by}, certificate ${survey.calibration_certificate}; ` +
    `standard uncertainty of g ${survey.uncertainty}; next survey due ${survey.calibration_due}` +
    `${survey.overdue ? ' — OVERDUE: the survey was due before this run was made' : ''}`;
  return { role, overdue: Boolean(survey.overdue), missing: false, text };
}

/** The site's gravity and how it was obtained (with the 1-sigma the calibration used, when stated). */
export function gravityStatement(g) {
  if (!g) return '—';
  const value = `${num(g.value_mps2, 8)} m/s²`;
  const sigma = typeof g.sigma_mps2 === 'number' ? `; standard uncertainty ${num(g.sigma_mps2, 2)} m/s²` : '';
  return g.source === 'configured'
    ? `${value}, configured (measured at the table's axis intersection)${sigma}`
    : `${value}, WGS-84 normal gravity formula at latitude ${num(g.latitude_deg, 6)}°, height ${num(g.height_m, 4)} m${sigma}`;
}

/** The uncertainty statement beside the coefficient table. */
export const UNCERTAINTY_TEXT =
  `u (k = 1): combined standard uncertainty, the estimator's own (type A) with the type B sources of its stage (the ` +
  `table's certificate, the site's gravity, the start model's terms: the budget annex); U = k u, coverage factor k = ${COVERAGE_K}, ` +
  'about 95 % for a normal distribution. "Not determined": this run did not estimate it.';

/** The conventions, stated on the certificate itself (the model's frame: "instrument" or "body"). */
export function conventionsText(frame) {
  const body = frame === 'body';
  return [
    'Sensor model, for each triad (gyros, accelerometers): u = D · S · i + b + n. Here i is the true input ' +
      '(angular rate relative to inertial space; specific force) resolved in the reference frame, S = diag(1 + s) the ' +
      'scale-factor errors (gyros: one value for positive and one for negative input rates), D the misalignment matrix ' +
      'with rows (1, +xz, −xy), (−yz, 1, +yx), (+zy, −zx, 1), b the bias and n the noise; u is the output. ' +
      'A delay τ means the output at time t reflects the input at t − τ; proof-mass offsets are the positions of the ' +
      'y and z accelerometers\' proof masses relative to the x proof mass.',
    `Frames: the coefficients are given in the ${body ? 'body frame, built on the accelerometer axes (X along ' +
      'accelerometer x, Y in the plane of accelerometers x and y, Z completing a right-handed set)' :
      'instrument frame, defined by the unit\'s mounting surfaces (axes X0, Y0, Z0 as marked on the unit)'}. ` +
      'Misalignment "ab" is a rotation of sensor axis a about reference axis b; all angles are positive ' +
      'right-handed (counter-clockwise when looking from the tip of the axis towards the origin).',
    'Units: gyro bias in °/h, accelerometer bias in m/s², scale factors in ppm (10⁻⁶), misalignments in ' +
      'arc seconds (″), delays in µs, proof-mass offsets in mm, angle random walk in °/√h, velocity random walk in (m/s)/√h. ' +
      'To correct a measurement, subtract b and apply the inverse of D · S.',
  ];
}
