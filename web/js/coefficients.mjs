// Coefficients of an imucal-imu-model/1 (formats.md) as the flat names the live estimates use
// ("gyro.bias_dph.x", "accel.misalignment_arcsec.yz"), their groups, and their units, which the
// API puts in every name (docs/api.md: "_dph", "_ppm", "_arcsec", ...). Which names exist, their
// groups and their titles are imucald's (schema.mjs); the units follow from a name's suffix.

import { schema } from './schema.mjs';

/**
 * The groups the tables list coefficients under, in order ({key, title, unit}): imucald's
 * (GET /api/schema). A coefficient is in the group whose key and a dot begin its name.
 */
export function groups() {
  return schema().groups;
}

const UNITS = {
  dph: '°/h', ppm: 'ppm', arcsec: '″', mps2: 'm/s²', mm: 'mm', us: 'µs', m: 'm', s: 's', C: '°C',
  deg: '°', dps: '°/s', hz: 'Hz', rth: '/√h', mps: 'm/s',
};

/** The unit of a coefficient or quantity from its name: "gyro.bias_dph.x" -> "°/h". */
export function unitOf(name) {
  const parts = name.split('.');
  for (let i = parts.length - 1; i >= 0; i--) {
    const p = parts[i];
    if (p === 'arw_deg_rth') return '°/√h';
    if (p === 'vrw_mps_rth') return 'm/s/√h';
    if (p.endsWith('_dph_rth')) return '°/h/√h';
    if (p.endsWith('_mps2_rth')) return 'm/s²/√h';
    if (p.endsWith('_dph_per_g')) return '°/h/g';
    if (p.endsWith('_ug_per_g2')) return 'µg/g²';
    if (p.endsWith('_ug_per_g3')) return 'µg/g³';
    const m = /_([A-Za-z0-9]+)$/.exec(p);
    if (m && UNITS[m[1]]) return UNITS[m[1]];
  }
  return '';
}

/** A quantity's name for people, its unit left to unitOf: "accel_residual_rms_mps2" -> "accel residual rms". */
export function labelOf(key) {
  const m = /^(.*?)_(deg_rth|mps_rth|dph_rth|mps2_rth|[A-Za-z0-9]+)$/.exec(key);
  const bare = m && (UNITS[m[2]] || m[2].endsWith('_rth')) ? m[1] : key;
  return bare.replace(/_/g, ' ');
}

export function groupOf(name) {
  return groups().find((g) => name.startsWith(`${g.key}.`)) || null;
}

const AXES = ['x', 'y', 'z'];
const SKIP = new Set(['format', 'frame', 'sigma', 'thermal', 'status', 'body_to_instrument_deg', 'comment']);

/**
 * Flattens the gyro and accel sections of a model (or of its sigma) into name -> number:
 * arrays of three become .x/.y/.z, objects recurse.
 */
export function flatten(model) {
  const out = new Map();
  const { byKey } = schema();
  const walk = (value, prefix) => {
    if (typeof value === 'number') out.set(prefix, value);
    // A polynomial's terms (the gyro's scale nonlinearity: one to three, c1 c2 c3, formats.md):
    // the names imucald gives them say which arrays these are.
    else if (Array.isArray(value) && byKey.has(`${prefix}.c1`))
      value.forEach((v, i) => { if (typeof v === 'number') out.set(`${prefix}.c${i + 1}`, v); });
    // A 3x3 matrix (the g-sensitivity: rows gyro x y z, columns specific force along x y z).
    else if (Array.isArray(value) && value.length === 3 && value.every((r) => Array.isArray(r) && r.length === 3))
      value.forEach((r, i) => r.forEach((v, k) => { if (typeof v === 'number') out.set(`${prefix}.${AXES[i]}.${AXES[k]}`, v); }));
    else if (Array.isArray(value) && value.length === 3 && value.every((v) => typeof v === 'number'))
      value.forEach((v, i) => out.set(`${prefix}.${AXES[i]}`, v));
    else if (value && typeof value === 'object' && !Array.isArray(value))
      for (const [k, v] of Object.entries(value)) if (!SKIP.has(k) && !k.startsWith('_')) walk(v, `${prefix}.${k}`);
  };
  for (const triad of ['gyro', 'accel']) if (model && model[triad]) walk(model[triad], triad);
  return out;
}

/** Sort key: the groups in imucald's order, then everything else. */
export function orderOf(name) {
  const all = groups();
  const gi = all.findIndex((g) => name.startsWith(`${g.key}.`));
  return gi >= 0 ? gi : all.length;
}

/**
 * Rows for the result table: [{name, group, unit, estimate, sigma, truth, error, ratio,
 * byDefinition}] from the model (with its sigma section) and, in a simulated run, the truth IN
 * THE MODEL'S FRAME: imucald's comparison (GET /api/campaigns/{id}/truth: {frame, truth,
 * zero_by_definition, rows}), which turned the truth into the model's frame, or a truth model
 * already in that frame. A coefficient that is zero by the frame's definition (body frame:
 * accelerometer xy, xz, yx) has no truth, error or ratio: it is not judged.
 */
export function coefficientRows(model, truth) {
  const est = flatten(model);
  const sig = flatten(model?.sigma);
  const comparison = truth && typeof truth === 'object' && Array.isArray(truth.rows) ? truth : null;
  const truthModel = comparison ? comparison.truth : truth;
  const tru = truthModel && typeof truthModel === 'object' ? flatten(truthModel) : null;
  const byDefinition = new Set(comparison?.zero_by_definition || []);
  const rows = [];
  for (const [name, estimate] of est) {
    const isNoise = name.includes('.noise.');
    const zero = byDefinition.has(name);
    const sigma = sig.has(name) && !zero ? sig.get(name) : null;
    const t = tru && tru.has(name) && !zero ? tru.get(name) : null;
    const error = t === null ? null : estimate - t;
    const ratio = error !== null && sigma > 0 ? error / sigma : null;
    // Lever arms and delays the stage did not estimate come as zeros with a zero sigma.
    const estimated = zero || (isNoise || sigma === null ? estimate !== 0 || isNoise : !(sigma === 0 && estimate === 0));
    rows.push({ name, group: groupOf(name)?.title || (isNoise ? 'Noise' : 'Other'), unit: unitOf(name),
      estimate, sigma, truth: t, error, ratio, estimated, byDefinition: zero });
  }
  rows.sort((a, b) => orderOf(a.name) - orderOf(b.name) || 0);
  return rows;
}

// Names of the noise terms, which are not coefficients (no sigma) and so not in imucald's schema.
const NOISE_NAMES = {
  arw_deg_rth: 'angle random walk', vrw_mps_rth: 'velocity random walk',
  bias_instability_dph: 'bias instability', bias_instability_mps2: 'bias instability',
  bias_corr_time_s: 'bias correlation time', bias_rw_dph_rth: 'rate random walk', bias_rw_mps2_rth: 'bias random walk',
};
const TRIADS = { gyro: 'Gyro', accel: 'Accelerometer' };

/**
 * A coefficient's name for people, without its unit (unitOf gives that): imucald's title
 * ("gyro.bias_dph.x" -> "Gyro bias, x axis"); a noise term from its name ("gyro.noise.arw_deg_rth"
 * -> "Gyro angle random walk"); another name in a group (a limit's key) from the group's title.
 * Unknown names come back as they are.
 */
export function coefficientName(key) {
  const known = schema().byKey.get(key);
  if (known) return known.title;
  const parts = key.split('.');
  const triad = TRIADS[parts[0]];
  if (triad && parts[1] === 'noise' && parts.length === 3)
    return `${triad} ${NOISE_NAMES[parts[2]] || labelOf(parts[2])}`;
  const group = groupOf(key);
  if (!group) return key;
  const rest = key.slice(group.key.length + 1);
  return AXES.includes(rest) ? `${group.title}, ${rest} axis` : `${group.title}, ${rest}`;
}

/**
 * Whether a run determined a coefficient: the daemon's rule (daemon/production/acceptance.hpp,
 * determined()), so that the certificate says "not determined" exactly where a verdict does.
 * A run determines a coefficient when it gives it a positive sigma; noise terms carry no sigma
 * and are determined when positive. What a stage carried over unestimated has sigma 0 or none.
 */
export function determined(key, value, sigma) {
  if (key.includes('.noise.')) return typeof value === 'number' && value > 0;
  return typeof sigma === 'number' && Number.isFinite(sigma) && sigma > 0;
}
