// The campaign builder's pure parts, without the DOM (so Node tests them too): the keys of each
// program segment type (docs/programs.md), parsing what is typed into them, and sorting the
// daemon's problems by the segment or field they are about.

// Keys per segment type (docs/programs.md). kind: number | vec3 | vec3list | axis | axes | numlist | text
export const SEGMENT_TYPES = {
  hold: [
    { key: 'duration_s', kind: 'number', required: true, positive: true, label: 'duration s' },
    { key: 'kind', kind: 'text', label: 'kind' },
  ],
  move: [
    { key: 'to_deg', kind: 'vec3', required: true, label: 'to deg (o, m, i)' },
    { key: 'duration_s', kind: 'number', positive: true, label: 'duration s' },
  ],
  positions: [
    { key: 'positions_deg', kind: 'vec3list', required: true, label: 'positions deg (o, m, i; one per line)' },
    { key: 'dwell_s', kind: 'number', required: true, positive: true, label: 'dwell s' },
    { key: 'move_s', kind: 'number', positive: true, label: 'move s' },
  ],
  tilts: [
    { key: 'positions_deg', kind: 'vec3list', required: true, label: 'positions deg (o, m, i; one per line)' },
    { key: 'dwell_s', kind: 'number', required: true, positive: true, label: 'dwell s' },
    { key: 'move_s', kind: 'number', positive: true, label: 'move s' },
  ],
  rate: [
    { key: 'axis', kind: 'axis', required: true, label: 'axis' },
    { key: 'rate_dps', kind: 'number', required: true, nonzero: true, label: 'rate deg/s' },
    { key: 'revolutions', kind: 'number', positive: true, label: 'revolutions' },
    { key: 'duration_s', kind: 'number', positive: true, label: 'duration s' },
    { key: 'accel_dps2', kind: 'number', positive: true, label: 'accel deg/s²' },
  ],
  sine: [
    { key: 'axis', kind: 'axis', required: true, label: 'axis' },
    { key: 'amplitude_deg', kind: 'number', required: true, label: 'amplitude deg' },
    { key: 'period_s', kind: 'number', required: true, positive: true, label: 'period s' },
    { key: 'cycles', kind: 'number', required: true, positive: true, label: 'cycles' },
    { key: 'phase_deg', kind: 'number', label: 'phase deg' },
    { key: 'ramp_s', kind: 'number', nonnegative: true, label: 'ramp s' },
  ],
  coning: [
    { key: 'axes', kind: 'axes', required: true, label: 'axes' },
    { key: 'amplitude_deg', kind: 'numlist', required: true, label: 'amplitude deg (1 or 2)' },
    { key: 'period_s', kind: 'number', required: true, positive: true, label: 'period s' },
    { key: 'cycles', kind: 'number', required: true, positive: true, label: 'cycles' },
    { key: 'ramp_s', kind: 'number', nonnegative: true, label: 'ramp s' },
  ],
  // The IMU is switched off and on before it (imucald asks the operator and waits).
  'power-cycle': [
    { key: 'duration_s', kind: 'number', required: true, positive: true, label: 'rest after power-on s' },
  ],
};
export const NEW_SEGMENT = {
  hold: { duration_s: 10 }, move: { to_deg: [0, 0, 0] }, positions: { positions_deg: [[0, 0, 0]], dwell_s: 10 },
  tilts: { positions_deg: [[0, 10, 0]], dwell_s: 60 }, rate: { axis: 'outer', rate_dps: 20, revolutions: 2 },
  sine: { axis: 'outer', amplitude_deg: 20, period_s: 2, cycles: 10, ramp_s: 2 },
  coning: { axes: ['middle', 'inner'], amplitude_deg: 10, period_s: 10, cycles: 10 },
  'power-cycle': { duration_s: 10 },
};
export const AXIS_NAMES = ['outer', 'middle', 'inner'];

// ---- parsing of the text fields ---------------------------------------------------------------

export function parseNumber(text) {
  const t = text.trim().replace(',', '.');
  if (t === '') return { empty: true };
  if (!/^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(t)) return { error: 'not a number' };
  return { value: Number(t) };
}

export function parseNumbers(text) {
  const parts = text.split(/[\s,]+/).filter(Boolean);
  const out = [];
  for (const p of parts) {
    const n = parseNumber(p);
    if (n.error) return { error: `"${p}" is not a number` };
    out.push(n.value);
  }
  return { value: out };
}

export function formatValue(field, value) {
  if (value === undefined || value === null) return '';
  switch (field.kind) {
    case 'vec3': case 'numlist': case 'axes': return Array.isArray(value) ? value.join(', ') : String(value);
    case 'vec3list': return Array.isArray(value) ? value.map((p) => (Array.isArray(p) ? p.join(', ') : String(p))).join('\n') : '';
    default: return String(value);
  }
}

/** Parses a field's text; {value} | {empty} | {error}. */
export function parseField(field, text) {
  if (field.kind === 'text' || field.kind === 'axis') return text.trim() === '' ? { empty: true } : { value: text.trim() };
  if (field.kind === 'number') {
    const n = parseNumber(text);
    if (n.empty || n.error) return n;
    if (field.positive && !(n.value > 0)) return { error: 'must be greater than 0' };
    if (field.nonnegative && n.value < 0) return { error: 'must not be negative' };
    if (field.nonzero && n.value === 0) return { error: 'must not be 0' };
    return n;
  }
  if (field.kind === 'vec3') {
    if (!text.trim()) return { empty: true };
    const r = parseNumbers(text);
    if (r.error) return r;
    if (r.value.length !== 3) return { error: 'three angles: outer, middle, inner' };
    return r;
  }
  if (field.kind === 'numlist') {
    if (!text.trim()) return { empty: true };
    const r = parseNumbers(text);
    if (r.error) return r;
    if (r.value.length < 1 || r.value.length > 2) return { error: 'one or two numbers' };
    return { value: r.value.length === 1 ? r.value[0] : r.value };
  }
  if (field.kind === 'vec3list') {
    if (!text.trim()) return { empty: true };
    const list = [];
    for (const chunk of text.split(/[;\n]+/).map((s) => s.trim()).filter(Boolean)) {
      const r = parseNumbers(chunk);
      if (r.error) return r;
      if (r.value.length !== 3) return { error: `"${chunk}": each position has three angles` };
      list.push(r.value);
    }
    return list.length ? { value: list } : { empty: true };
  }
  if (field.kind === 'axes') {
    const parts = text.split(/[\s,]+/).filter(Boolean);
    if (!parts.length) return { empty: true };
    if (parts.length !== 2 || parts.some((p) => !AXIS_NAMES.includes(p)) || parts[0] === parts[1])
      return { error: 'two different axes of outer, middle, inner' };
    return { value: parts };
  }
  return { value: text };
}

// ---- problems from the daemon, by segment and by field ---------------------------------------

/**
 * Splits the daemon's problems into those of a program segment (by index into the source
 * segments), those of a campaign field (by path) and the rest. A compiled segment of a
 * `positions` segment "pos" is named "pos-01", its moves "to-pos-02"; a program of an array has
 * the program's name as prefix ("direct/pos-01").
 */
export function mapProblems(problems, segments) {
  const bySegment = new Map();
  const byField = new Map();
  const general = [];
  const add = (map, key, text) => { if (!map.has(key)) map.set(key, []); map.get(key).push(text); };
  for (const p of problems) {
    let m = /program segment (\d+) '([^']*)'/.exec(p);
    if (m && Number(m[1]) >= 1 && Number(m[1]) <= segments.length) {
      add(bySegment, Number(m[1]) - 1, p);
      continue;
    }
    m = /segment '([^']+)'/.exec(p);
    if (m) {
      const i = sourceIndex(m[1], segments);
      if (i >= 0) { add(bySegment, i, p); continue; }
    }
    m = /^campaign\.(?!program)([A-Za-z_][\w.[\]]*)/.exec(p);
    if (m) { add(byField, m[1], p); continue; }
    general.push(p);
  }
  return { bySegment, byField, general };
}

// The campaign fields as the builder's form names them, by their JSON path (docs/api.md): one
// table for the labels and for the daemon's problems about them, so that "campaign.rate_hz: ..."
// reads "rate (Hz): ..." (issue 18, item 3).
export const CAMPAIGN_FIELD_LABELS = {
  name: 'name',
  estimators: 'estimators',
  rate_hz: 'rate (Hz)',
  time_scale: 'time scale',
  seed: 'seed',
  truth: 'truth (simulation)',
  'imu.serial': 'serial',
  'imu.part_number': 'part number',
  'imu.firmware': 'firmware',
  'imu.customer': 'customer',
  'imu.notes': 'notes',
  'chamber.setpoint_C': 'set point °C',
  'chamber.tolerance_C': 'tolerance °C',
  chamber: 'chamber',
  sim_faults: 'simulated faults',
};

// The form's name of a campaign field path: "chamber.steps[1].at_s" -> "chamber step 2 at_s".
export function campaignFieldLabel(path) {
  if (CAMPAIGN_FIELD_LABELS[path]) return CAMPAIGN_FIELD_LABELS[path];
  const m = /^(chamber\.steps|sim_faults)\[(\d+)\](?:\.(\w+))?$/.exec(path);
  if (m) return `${m[1] === 'sim_faults' ? 'fault' : 'chamber step'} ${Number(m[2]) + 1}${m[3] ? ` ${m[3].replace(/_/g, ' ')}` : ''}`;
  return path.replace(/_/g, ' ');
}

// A daemon problem about a campaign field, with the field named as the form names it.
export function problemForPeople(problem) {
  const m = /^campaign\.(?!program)([A-Za-z_][\w.[\]]*?):? (?=\S)/.exec(problem);
  return m ? `${campaignFieldLabel(m[1])}: ${problem.slice(m[0].length)}` : problem;
}

export function sourceIndex(compiled, segments) {
  const bare = compiled.includes('/') ? compiled.slice(compiled.lastIndexOf('/') + 1) : compiled;
  let i = segments.findIndex((s) => s.name === bare);
  if (i >= 0) return i;
  i = segments.findIndex((s) => s.name && (bare.startsWith(`${s.name}-`) || bare.startsWith(`to-${s.name}-`) || bare === `to-${s.name}`));
  return i;
}

// The same violation is reported at every moment it happens ("(t=10.0 s)"): say it once with
// the times. The "campaign.program: " prefix says nothing beside a segment.
export function compress(list) {
  const groups = new Map();
  for (const p of list) {
    const m = /\s*\(t=([-\d.]+) s\)/.exec(p);
    const key = m ? p.replace(m[0], '') : p;
    if (!groups.has(key)) groups.set(key, { first: p, times: [] });
    if (m) groups.get(key).times.push(m[1]);
  }
  return [...groups].map(([text, g]) => (g.times.length > 1 ? `${text} (at t = ${g.times.join(', ')} s)` : g.first))
    .map((p) => p.replace(/^campaign\.program: /, ''));
}


/** JSON with every object's keys in order: the same program however its edits ordered them. */
export function canonical(value) {
  return JSON.stringify(value, (key, v) => (v && typeof v === 'object' && !Array.isArray(v)
    ? Object.fromEntries(Object.keys(v).sort().map((k) => [k, v[k]])) : v));
}
