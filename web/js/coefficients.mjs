// Coefficients of an imucal-imu-model/1 (formats.md) as the flat names the live estimates use
// ("gyro.bias_dph.x", "accel.misalignment_arcsec.yz"), their groups, and their units, which the
// API puts in every name (docs/api.md: "_dph", "_ppm", "_arcsec", ...).

export const GROUPS = [
  { key: 'gyro.bias_dph', title: 'Gyro bias' },
  { key: 'gyro.scale_pos_ppm', title: 'Gyro scale factor (+ rates)' },
  { key: 'gyro.scale_neg_ppm', title: 'Gyro scale factor (− rates)' },
  { key: 'gyro.misalignment_arcsec', title: 'Gyro misalignment' },
  { key: 'accel.bias_mps2', title: 'Accelerometer bias' },
  { key: 'accel.scale_ppm', title: 'Accelerometer scale factor' },
  { key: 'accel.misalignment_arcsec', title: 'Accelerometer misalignment' },
  // The lever-arm stage and stage 3 estimate these too.
  { key: 'gyro.delay_us', title: 'Gyro delay' },
  { key: 'accel.delay_us', title: 'Accelerometer delay' },
  { key: 'accel.lever_arm_mm', title: 'Proof-mass offsets' },
];

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
  return GROUPS.find((g) => name.startsWith(`${g.key}.`)) || null;
}

const AXES = ['x', 'y', 'z'];
const SKIP = new Set(['format', 'frame', 'sigma', 'thermal', 'status', 'body_to_instrument_deg', 'comment']);

/**
 * Flattens the gyro and accel sections of a model (or of its sigma) into name -> number:
 * arrays of three become .x/.y/.z, objects recurse.
 */
export function flatten(model) {
  const out = new Map();
  const walk = (value, prefix) => {
    if (typeof value === 'number') out.set(prefix, value);
    else if (Array.isArray(value) && value.length === 3 && value.every((v) => typeof v === 'number'))
      value.forEach((v, i) => out.set(`${prefix}.${AXES[i]}`, v));
    else if (value && typeof value === 'object' && !Array.isArray(value))
      for (const [k, v] of Object.entries(value)) if (!SKIP.has(k) && !k.startsWith('_')) walk(v, `${prefix}.${k}`);
  };
  for (const triad of ['gyro', 'accel']) if (model && model[triad]) walk(model[triad], triad);
  return out;
}

/** Sort key: the groups above in order, then everything else by name. */
export function orderOf(name) {
  const gi = GROUPS.findIndex((g) => name.startsWith(`${g.key}.`));
  return gi >= 0 ? gi : GROUPS.length;
}

/**
 * Rows for the result table: [{name, group, unit, estimate, sigma, truth, error, ratio}] from the
 * model (with its sigma section) and, in a simulated run, the truth model.
 */
export function coefficientRows(model, truth) {
  const est = flatten(model);
  const sig = flatten(model?.sigma);
  const tru = truth && typeof truth === 'object' ? flatten(truth) : null;
  const rows = [];
  for (const [name, estimate] of est) {
    const isNoise = name.includes('.noise.');
    const sigma = sig.has(name) ? sig.get(name) : null;
    const t = tru && tru.has(name) ? tru.get(name) : null;
    const error = t === null ? null : estimate - t;
    const ratio = error !== null && sigma > 0 ? error / sigma : null;
    // Lever arms and delays the stage did not estimate come as zeros with a zero sigma.
    const estimated = isNoise || sigma === null ? estimate !== 0 || isNoise : !(sigma === 0 && estimate === 0);
    rows.push({ name, group: groupOf(name)?.title || (isNoise ? 'Noise' : 'Other'), unit: unitOf(name),
      estimate, sigma, truth: t, error, ratio, estimated });
  }
  rows.sort((a, b) => orderOf(a.name) - orderOf(b.name) || 0);
  return rows;
}
