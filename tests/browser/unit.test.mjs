// Unit tests of the web UI's pure modules, in Node without a browser (fast, no Chromium needed):
// the bounded decimating series behind the live plots, the builder's parsing and its sorting of
// the daemon's problems by segment, and the flattening of an imucal-imu-model/1 into coefficients.
import test from 'node:test';
import assert from 'node:assert/strict';
import { Series, BoundedList } from '../../web/js/series.mjs';
import { parseField, SEGMENT_TYPES, mapProblems, compress } from '../../web/js/program_edit.mjs';
import { flatten, coefficientRows, unitOf, labelOf } from '../../web/js/coefficients.mjs';
import { alarmStatus, needsAttention, applyAlarm, alarmStatusText, alarmSummary } from '../../web/js/alarms.mjs';
import { runOutcome } from '../../web/js/outcome.mjs';
import { readFileSync } from 'node:fs';
import { setSchema, schema, schemaLoaded, loadSchema } from '../../web/js/schema.mjs';

// The coefficients' names, groups and targets as imucald serves them (GET /api/schema); the file
// is checked against the service by test_daemon's Schema.TheBrowserTestsCopyIsWhatTheServiceServes.
const SCHEMA_DOC = JSON.parse(readFileSync(new URL('./schema.json', import.meta.url), 'utf8'));

test('the schema: an error before it is loaded, asked for once, then every name by its key', async () => {
  assert.equal(schemaLoaded(), false);
  assert.throws(() => schema(), /not loaded/);
  let asked = 0;
  const get = async (path) => { asked++; assert.equal(path, '/api/schema'); return SCHEMA_DOC; };
  const [a, b] = await Promise.all([loadSchema(get), loadSchema(get)]);
  assert.equal(asked, 1, 'one request for two callers');
  assert.equal(a, b);
  await loadSchema(get);
  assert.equal(asked, 1, 'kept once loaded');
  assert.equal(schema().byKey.get('gyro.bias_dph.x').group, 'gyro.bias_dph');
  assert.equal(schema().groups[0].key, 'gyro.bias_dph', 'the groups in the order the tables show them');
  assert.equal(schema().seedTargets['gyro.misalignment_arcsec'], 0.1);
  assert.ok(Object.isFrozen(schema().seedTargets), 'a caller edits a copy (plan.mjs seedTargets())');
});

test("coefficients by imucald's schema: groups, order, names, the polynomial's terms", async () => {
  const { groups, groupOf, orderOf, coefficientName } = await import('../../web/js/coefficients.mjs');
  assert.deepEqual(groups(), SCHEMA_DOC.groups);
  assert.equal(groupOf('accel.lever_arm_mm.z.y').title, 'Proof-mass offsets', 'both offsets are one group');
  assert.equal(groupOf('gyro.noise.arw_deg_rth'), null);
  assert.ok(orderOf('gyro.delay_us.x') > orderOf('accel.k3_ug_per_g3.x'), 'delays after the nonlinear terms, as the tables show');
  assert.equal(orderOf('something.else'), groups().length);
  // A name in a group that is no coefficient (a limit's key for part of a group).
  assert.equal(coefficientName('gyro.scale_nonlinear_ppm.x'), 'Gyro scale nonlinearity, x axis');
  assert.equal(coefficientName('gyro.g_sensitivity_dph_per_g.x'), 'Gyro g-sensitivity, x axis');
  assert.equal(coefficientName('gyro.g_sensitivity_dph_per_g.q'), 'Gyro g-sensitivity, q');
  assert.equal(coefficientName('nothing.known'), 'nothing.known');
  // One to three terms per axis, named as imucald names them; a vector of three stays a vector.
  const flat = flatten({ gyro: { scale_nonlinear_ppm: { x: [1, 2], y: [3, 4, 5] }, bias_dph: [1, 2, 3] } });
  assert.deepEqual([...flat.keys()], ['gyro.scale_nonlinear_ppm.x.c1', 'gyro.scale_nonlinear_ppm.x.c2',
    'gyro.scale_nonlinear_ppm.y.c1', 'gyro.scale_nonlinear_ppm.y.c2', 'gyro.scale_nonlinear_ppm.y.c3',
    'gyro.bias_dph.x', 'gyro.bias_dph.y', 'gyro.bias_dph.z']);
  for (const k of flat.keys()) assert.ok(schema().byKey.has(k), `${k} is one of imucald's coefficients`);
});

test('the limits form names its example key after imucald\'s first coefficient', async () => {
  const { formToLimits } = await import('../../web/js/limits_form.mjs');
  const { problems } = formToLimits({ parts: [{ partNumber: 'PN', rows: [{ key: 'bias', maxAbs: '1', maxSigma: '' }] }] });
  const first = SCHEMA_DOC.coefficients[0];
  assert.deepEqual(problems.map((p) => p.message),
    [`A key is a coefficient's name such as ${first.key}, or a group such as ${first.group}.`]);
});

test('a failed request for the schema is asked again by the next caller', async () => {
  const { loadSchema: load2 } = await import(`../../web/js/schema.mjs?again`);
  let asked = 0;
  const get = async () => { asked++; if (asked === 1) throw new Error('offline'); return SCHEMA_DOC; };
  await assert.rejects(load2(get), /offline/);
  await load2(get);
  assert.equal(asked, 2);
});

test('a 12 h run at 10 Hz stays within the series bounds and covers the whole run', () => {
  const s = new Series(3, { recentCapacity: 6000, historyCapacity: 2000 });
  const n = 12 * 3600 * 10;
  for (let i = 0; i < n; i++) s.push(i / 10, [i, -i, Math.sin(i)]);
  assert.equal(s.length, n);
  assert.ok(s.heldPoints <= 8000, `held ${s.heldPoints}`);
  const whole = s.view(Infinity);
  assert.ok(whole[0].length <= 2001, `whole-run view has ${whole[0].length} points`);
  assert.equal(whole[0][0], 0);
  assert.equal(whole[0][whole[0].length - 1], (n - 1) / 10, 'ends on the newest sample');
  for (let k = 1; k < whole[0].length; k++) assert.ok(whole[0][k] > whole[0][k - 1], 'times increase');
  assert.equal(whole[1][whole[1].length - 1], n - 1);
  const recent = s.view(60);
  assert.equal(recent[0].length, 601, 'the last minute at full rate');
  assert.equal(recent[0][0], (n - 1) / 10 - 60);
});

test('views are thinned to maxPoints and keep the newest sample', () => {
  const s = new Series(1, { recentCapacity: 10000, historyCapacity: 100 });
  for (let i = 0; i < 9999; i++) s.push(i, [i]);
  const v = s.view(Infinity, 1000);
  assert.ok(v[0].length <= 1001);
  assert.equal(v[0][v[0].length - 1], 9998);
});

test('a sample older than the last is dropped; missing values become gaps', () => {
  const s = new Series(2);
  assert.ok(s.push(1, [1, 2]));
  assert.equal(s.push(0.5, [3, 4]), false);
  assert.ok(s.push(2, [NaN, undefined]));
  const [t, a, b] = s.view();
  assert.deepEqual(t, [1, 2]);
  assert.deepEqual(a, [1, null]);
  assert.deepEqual(b, [2, null]);
  assert.ok(Number.isNaN(s.last(0)));
});

test('the history keeps a uniform stride after compaction', () => {
  const s = new Series(1, { recentCapacity: 10, historyCapacity: 8 });
  for (let i = 0; i < 100; i++) s.push(i, [i]);
  const [t] = s.view(Infinity);
  const steps = new Set();
  for (let k = 1; k < t.length - 1; k++) steps.add(t[k] - t[k - 1]);
  assert.equal(steps.size, 1, `one stride in the history: ${[...steps]}`);
});

test('a bounded list keeps the newest items', () => {
  const l = new BoundedList(100);
  for (let i = 0; i < 1000; i++) l.push(i);
  assert.ok(l.items.length <= 100);
  assert.equal(l.items[l.items.length - 1], 999);
});

test('segment fields are parsed before anything is sent', () => {
  const f = (type, key) => SEGMENT_TYPES[type].find((x) => x.key === key);
  assert.deepEqual(parseField(f('rate', 'rate_dps'), ' -30 '), { value: -30 });
  assert.equal(parseField(f('rate', 'rate_dps'), '0').error, 'must not be 0');
  assert.equal(parseField(f('rate', 'rate_dps'), 'fast').error, 'not a number');
  assert.equal(parseField(f('hold', 'duration_s'), '-1').error, 'must be greater than 0');
  assert.deepEqual(parseField(f('hold', 'duration_s'), ''), { empty: true });
  assert.deepEqual(parseField(f('move', 'to_deg'), '0, 90 90'), { value: [0, 90, 90] });
  assert.match(parseField(f('move', 'to_deg'), '0, 90').error, /three angles/);
  assert.deepEqual(parseField(f('positions', 'positions_deg'), '0,0,0; 180,0,0'), { value: [[0, 0, 0], [180, 0, 0]] });
  assert.match(parseField(f('positions', 'positions_deg'), '0,0,0; 180,0').error, /three angles/);
  assert.deepEqual(parseField(f('coning', 'axes'), 'middle, inner'), { value: ['middle', 'inner'] });
  assert.ok(parseField(f('coning', 'axes'), 'middle, middle').error);
  assert.deepEqual(parseField(f('coning', 'amplitude_deg'), '10'), { value: 10 });
  assert.deepEqual(parseField(f('coning', 'amplitude_deg'), '10 5'), { value: [10, 5] });
});

test("the daemon's problems land beside their segment or field", () => {
  const segments = [{ name: 'start' }, { name: 'pos' }, { name: 'rate-z+' }, { name: 'fast2' }];
  const problems = [
    "campaign.program: segment 'rate-z+' (t=10.0 s) axis outer: rate 400.000 deg/s exceeds the limit 300.000 deg/s",
    "campaign.program: segment 'rate-z+' (t=12.7 s) axis outer: rate 400.000 deg/s exceeds the limit 300.000 deg/s",
    "campaign.program: segment 'to-pos-03' (t=30.0 s) axis middle: acceleration 400 deg/s^2 exceeds the limit 300",
    "campaign.program: program segment 4 'fast2': too few revolutions for the ramps at this rate and acceleration",
    'campaign.chamber.setpoint_C 100.0 C is outside the chamber\'s limits -40.0 .. 85.0 C',
    'estimator "direct" needs at least 6 static segments and 3 rate segments; the program has 1 and 2',
  ];
  const m = mapProblems(problems, segments);
  assert.equal(m.bySegment.get(2).length, 2);
  assert.equal(m.bySegment.get(1).length, 1, 'a move of a positions segment belongs to it');
  assert.equal(m.bySegment.get(3).length, 1, 'by index when the daemon gives one');
  assert.deepEqual([...m.byField.keys()], ['chamber.setpoint_C']);
  assert.equal(m.general.length, 1);
  const c = compress(m.bySegment.get(2));
  assert.deepEqual(c, ["segment 'rate-z+' axis outer: rate 400.000 deg/s exceeds the limit 300.000 deg/s (at t = 10.0, 12.7 s)"]);
});

test("the daemon's problems about a campaign field name it as the form does", async () => {
  const { problemForPeople, campaignFieldLabel } = await import('../../web/js/program_edit.mjs');
  assert.equal(problemForPeople('campaign.rate_hz: 5000 Hz exceeds the limit of 4000 Hz'), 'rate (Hz): 5000 Hz exceeds the limit of 4000 Hz');
  assert.equal(problemForPeople("campaign.chamber.setpoint_C 100 °C is outside the chamber's limits -40 .. 85 °C"),
    "set point °C: 100 °C is outside the chamber's limits -40 .. 85 °C");
  assert.equal(problemForPeople('campaign.imu.serial must have 1 to 64 printable characters'), 'serial: must have 1 to 64 printable characters');
  assert.equal(campaignFieldLabel('chamber.steps[1].ramp_C_per_min'), 'chamber step 2 ramp C per min');
  assert.equal(campaignFieldLabel('sim_faults[0].at_s'), 'fault 1 at s');
  const programProblem = "campaign.program: segment 'x' (t=1.0 s) axis outer: rate 400 deg/s exceeds the limit 300 deg/s";
  assert.equal(problemForPeople(programProblem), programProblem, 'program problems are placed by segment, not renamed');
});

test('a model flattens to the names the live estimates use, with units', () => {
  const model = {
    format: 'imucal-imu-model/1', frame: 'instrument',
    gyro: { bias_dph: [1, 2, 3], scale_pos_ppm: [0, 0, 0], misalignment_arcsec: { xy: 5, xz: 0, yx: 0, yz: 0, zx: 0, zy: 0 }, noise: { arw_deg_rth: 0.01 } },
    accel: { bias_mps2: [0.001, 0, 0], lever_arm_mm: { y: [1, 2, 3], z: [0, 0, 0] } },
    sigma: { gyro: { bias_dph: [0.5, 0.5, 0.5] }, accel: { bias_mps2: [0.0001, 1, 1] } },
  };
  const f = flatten(model);
  assert.equal(f.get('gyro.bias_dph.z'), 3);
  assert.equal(f.get('gyro.misalignment_arcsec.xy'), 5);
  assert.equal(f.get('accel.lever_arm_mm.y.z'), 3);
  // The scale nonlinearity's one to three terms per gyro are c1, c2, c3, whatever their number.
  const nl = flatten({ gyro: { scale_nonlinear_ppm: { x: [1, 2, 3], y: [4, 5] } } });
  assert.deepEqual([...nl.entries()], [['gyro.scale_nonlinear_ppm.x.c1', 1], ['gyro.scale_nonlinear_ppm.x.c2', 2],
    ['gyro.scale_nonlinear_ppm.x.c3', 3], ['gyro.scale_nonlinear_ppm.y.c1', 4], ['gyro.scale_nonlinear_ppm.y.c2', 5]]);
  assert.equal(unitOf('gyro.scale_nonlinear_ppm.y.c2'), 'ppm');
  const gs = flatten({ gyro: { g_sensitivity_dph_per_g: [[1, 2, 3], [4, 5, 6], [7, 8, 9]] } });
  assert.equal(gs.get('gyro.g_sensitivity_dph_per_g.y.z'), 6);
  assert.equal(unitOf('gyro.g_sensitivity_dph_per_g.y.z'), '°/h/g');
  assert.equal(unitOf('gyro.bias_dph.x'), '°/h');
  assert.equal(unitOf('accel.bias_mps2.x'), 'm/s²');
  assert.equal(unitOf('gyro.noise.arw_deg_rth'), '°/√h');
  // Names for people: the unit suffix goes (unitOf shows it), underscores become spaces.
  assert.equal(labelOf('accel_residual_rms_mps2'), 'accel residual rms');
  assert.equal(labelOf('static_time_s'), 'static time');
  assert.equal(labelOf('arw_deg_rth'), 'arw');
  assert.equal(labelOf('statics'), 'statics');
  assert.equal(labelOf('source'), 'source');
  const truth = { gyro: { bias_dph: [0, 2, 0] }, accel: { bias_mps2: [0, 0, 0] } };
  const rows = coefficientRows(model, truth);
  const x = rows.find((r) => r.name === 'gyro.bias_dph.x');
  assert.deepEqual([x.estimate, x.sigma, x.truth, x.error, x.ratio], [1, 0.5, 0, 1, 2]);
  assert.equal(rows.find((r) => r.name === 'accel.bias_mps2.x').ratio, 10);
  assert.equal(rows[0].group, 'Gyro bias', 'groups in the order of the model');
});

test("a body-frame model against imucald's comparison: the truth in the model's frame, zeros by definition not judged", () => {
  const model = { frame: 'body', gyro: { misalignment_arcsec: { xy: 20, xz: 10, yx: -5, yz: 3, zx: 1, zy: 2 } },
    accel: { misalignment_arcsec: { xy: 0, xz: 0, yx: 0, yz: 4, zx: 5, zy: 6 } },
    sigma: { gyro: { misalignment_arcsec: { xy: 0.1, xz: 0.1, yx: 0.1, yz: 0.1, zx: 0.1, zy: 0.1 } },
      accel: { misalignment_arcsec: { xy: 0, xz: 0, yx: 0, yz: 0.2, zx: 0.2, zy: 0.2 } } } };
  // What GET /api/campaigns/{id}/truth answers: the truth already turned into the body frame.
  const comparison = { frame: 'body', truth_frame: 'instrument', converted: true,
    truth: { frame: 'body', gyro: { misalignment_arcsec: { xy: 20.05, xz: 10, yx: -5, yz: 3, zx: 1, zy: 2 } },
      accel: { misalignment_arcsec: { xy: 0, xz: 0, yx: 0, yz: 4.1, zx: 5, zy: 6 } } },
    zero_by_definition: ['accel.misalignment_arcsec.xy', 'accel.misalignment_arcsec.xz', 'accel.misalignment_arcsec.yx'],
    rows: [] };
  const rows = coefficientRows(model, comparison);
  const gxy = rows.find((r) => r.name === 'gyro.misalignment_arcsec.xy');
  assert.ok(Math.abs(gxy.ratio + 0.5) < 1e-9, `the body-frame truth is the one compared (${gxy.ratio})`);
  assert.ok(Math.abs(rows.find((r) => r.name === 'accel.misalignment_arcsec.yz').ratio + 0.5) < 1e-9);
  for (const k of ['xy', 'xz', 'yx']) {
    const r = rows.find((x) => x.name === `accel.misalignment_arcsec.${k}`);
    assert.equal(r.byDefinition, true, `accel ${k} is zero by definition of the body frame`);
    assert.deepEqual([r.sigma, r.truth, r.error, r.ratio], [null, null, null, null], 'and not judged (no 0 ± 0)');
    assert.equal(r.estimated, true, 'still listed');
  }
  assert.equal(rows.find((r) => r.name === 'accel.misalignment_arcsec.zy').byDefinition, false);
  // A plain truth model (no comparison) is still read as a model in the same frame.
  assert.equal(coefficientRows(model, comparison.truth).find((r) => r.name === 'accel.misalignment_arcsec.xy').byDefinition, false);
});

test("each stage's contribution to the final model, with stage 3's uncertainty reduction", async () => {
  const { contributionRows, stateOf } = await import('../../web/js/contributions.mjs');
  assert.deepEqual(stateOf('gyro.misalignment_arcsec.yz'), ['gyro_misalignment_rad', 3]);
  assert.deepEqual(stateOf('accel.misalignment_arcsec.zx'), ['accel_misalignment_rad', 1]);
  assert.deepEqual(stateOf('accel.lever_arm_mm.z.y'), ['accel_lever_arm_z_m', 1]);
  assert.equal(stateOf('accel.misalignment_arcsec.xy'), null, 'x-y is a body axis: not a state');
  const direct = { frame: 'body', gyro: { bias_dph: [0.04, -0.03, 0.06], delay_us: [0, 0, 0] }, accel: { lever_arm_mm: { y: [0, 0, 0], z: [0, 0, 0] } } };
  const lever = { frame: 'body', gyro: { bias_dph: [0.04, -0.03, 0.06], delay_us: [0, 0, 0] }, accel: { lever_arm_mm: { y: [10, -4, 6], z: [0, 0, 0] } } };
  const stage3 = { frame: 'body', gyro: { bias_dph: [0.041, -0.03, 0.06], delay_us: [2, 5, -3] }, accel: { lever_arm_mm: { y: [10.01, -4, 6], z: [0, 0, 0] } },
    sigma: { gyro: { bias_dph: [0.0003, 0.0003, 0.0003], delay_us: [0.5, 0.5, 0.5] }, accel: { lever_arm_mm: { y: [0.004, 0.004, 0.004], z: [0, 0, 0] } } } };
  const rows = contributionRows([{ stage: 'direct', model: direct }, { stage: 'lever-arm', model: lever }, { stage: 'stage3', model: stage3 }],
    { gyro_bias_radps: [3000, 3900, 3100], gyro_delay_s: [42, 42, 42] });
  const byName = new Map(rows.map((r) => [r.name, r]));
  const bx = byName.get('gyro.bias_dph.x');
  assert.deepEqual(bx.values, [0.04, 0.04, 0.041]);
  assert.ok(Math.abs(bx.changes[2] - 0.001) < 1e-12);
  assert.equal(bx.changes[1], 0);
  assert.equal(bx.reduction, 3000);
  assert.equal(bx.sigma, 0.0003);
  const ly = byName.get('accel.lever_arm_mm.y.x');
  assert.equal(ly.changes[1], 10, 'the lever-arm stage found the offset');
  assert.ok(Math.abs(ly.changes[2] - 0.01) < 1e-12, 'stage 3 refined it');
  assert.equal(byName.get('gyro.delay_us.y').reduction, 42);
  assert.equal(byName.has('accel.lever_arm_mm.z.x'), false, 'never estimated, zero everywhere: left out');
  assert.ok(rows.findIndex((r) => r.name.startsWith('gyro.bias')) < rows.findIndex((r) => r.name.startsWith('gyro.delay')));
});

test('the builder\'s prediction: each coefficient from the last stage that has it, judged against its target', async () => {
  const { predictionRows, summary, seedTargets, groupOfName } = await import('../../web/js/plan.mjs');
  const mine = seedTargets();
  mine['gyro.bias_dph'] = 1;
  assert.equal(seedTargets()['gyro.bias_dph'], 0.001, 'each caller has its own copy');
  const SEED_TARGETS = seedTargets();
  assert.deepEqual(Object.keys(SEED_TARGETS).slice(0, 2), ['gyro.bias_dph', 'gyro.scale_pos_ppm'], 'in the groups\' order');
  assert.equal(groupOfName('accel.lever_arm_mm.y.z'), 'accel.lever_arm_mm.y');
  const prediction = { stages: {
    direct: { estimates: { 'gyro.bias_dph.x': [0, 0.02], 'accel.scale_ppm.x': [0, 2], 'gyro.delay_us.x': [0, 0] } },
    navigation: { estimates: { 'gyro.bias_dph.x': [0, 0.0004], 'gyro.delay_us.x': [0, 1.5], 'accel.lever_arm_mm.y.x': [0, 0.01] } },
  } };
  const rows = predictionRows(prediction);
  assert.deepEqual(rows.map((r) => r.name), ['accel.lever_arm_mm.y.x', 'accel.scale_ppm.x', 'gyro.bias_dph.x', 'gyro.delay_us.x']);
  const byName = Object.fromEntries(rows.map((r) => [r.name, r]));
  assert.equal(byName['gyro.bias_dph.x'].stage, 'navigation', 'stage 3 refines stage 1');
  assert.equal(byName['gyro.bias_dph.x'].sigma, 0.0004);
  assert.equal(byName['gyro.bias_dph.x'].meets, true);
  assert.equal(byName['accel.scale_ppm.x'].stage, 'direct', 'kept from stage 1 when stage 3 does not have it');
  assert.equal(byName['accel.scale_ppm.x'].meets, false);
  assert.equal(byName['gyro.delay_us.x'].ratio, 1.5 / SEED_TARGETS['gyro.delay_us']);
  assert.equal(byName['accel.lever_arm_mm.y.x'].target, null, 'no target: no verdict');
  assert.equal(byName['accel.lever_arm_mm.y.x'].meets, null);
  const s = summary(rows);
  assert.deepEqual([s.met, s.judged], [1, 3]);
  assert.equal(s.worst.name, 'accel.scale_ppm.x');
  // Edited targets take over.
  const relaxed = predictionRows(prediction, { ...SEED_TARGETS, 'accel.scale_ppm': 5, 'gyro.delay_us': 2 });
  assert.equal(summary(relaxed).met, 3);
});

test('certificate rows: names with units, k = 2 beside k = 1, "not determined" instead of zeros, the verdict per coefficient', async () => {
  const { certificateRows, verdictStatement, partialStatement, overrideStatement, equipmentLines, gravityStatement, conventionsText,
    COVERAGE_K } = await import('../../web/js/certificate_rows.mjs');
  const { coefficientName } = await import('../../web/js/coefficients.mjs');
  assert.equal(coefficientName('gyro.bias_dph.x'), 'Gyro bias, x axis');
  assert.equal(coefficientName('accel.misalignment_arcsec.yz'), 'Accelerometer misalignment, sensor y about z');
  assert.equal(coefficientName('accel.lever_arm_mm.y.z'), 'Proof-mass offset of accelerometer y, z component');
  assert.equal(coefficientName('gyro.noise.bias_instability_dph'), 'Gyro bias instability');
  assert.equal(coefficientName('gyro.scale_nonlinear_ppm.z.c2'), 'Gyro scale nonlinearity, z axis, c2 (of q^2, q = |ω| / 100 °/s)');
  assert.equal(coefficientName('gyro.g_sensitivity_dph_per_g.x.z'), 'Gyro g-sensitivity of gyro x to specific force along z');
  assert.equal(coefficientName('accel.k2_ug_per_g2.y'), 'Accelerometer K2, y axis');
  // A direct run: delays and proof-mass offsets carried over (sigma 0), bias instability not
  // estimated (0, noise terms have no sigma), one misalignment whose sigma is null.
  const model = {
    format: 'imucal-imu-model/1', frame: 'instrument',
    gyro: { bias_dph: [0.06, -0.03, 0.02], scale_pos_ppm: [20, -10, 5], delay_us: [0, 0, 0],
      noise: { arw_deg_rth: 0.0005, bias_instability_dph: 0 } },
    accel: { bias_mps2: [1e-4, 2e-4, -1e-4], misalignment_arcsec: { xy: 3, xz: 4 }, lever_arm_mm: { y: [0, 0, 0], z: [0, 0, 0] } },
    sigma: { gyro: { bias_dph: [0.001, 0.001, 0.002], scale_pos_ppm: [1, 1, 1], delay_us: [0, 0, 0] },
      accel: { bias_mps2: [1e-6, 1e-6, 1e-6], misalignment_arcsec: { xy: 0.5, xz: null }, lever_arm_mm: { y: [0, 0, 0], z: [0, 0, 0] } } },
  };
  const verdict = { part_number: 'PN-1', pass: false, limits: 'limits.json', failures: 2, coefficients: [
    { key: 'gyro.bias_dph.x', value: 0.06, sigma: 0.001, limit_value: 0.05, limit_sigma: 0.002, pass: false, reason: '|value| 0.06 > limit 0.05' },
    { key: 'gyro.bias_dph.y', value: -0.03, sigma: 0.001, limit_value: 0.05, limit_sigma: null, pass: true, reason: '' },
    { key: 'accel.lever_arm_mm.y.x', value: 0, sigma: 0, limit_value: 1, limit_sigma: null, pass: false, reason: 'not determined by this run' },
  ] };
  const rows = certificateRows(model, verdict);
  const byKey = Object.fromEntries(rows.map((r) => [r.key, r]));
  const bx = byKey['gyro.bias_dph.x'];
  assert.equal(bx.name, 'Gyro bias, x axis');
  assert.equal(bx.unit, '°/h');
  assert.equal(COVERAGE_K, 2);
  assert.equal(bx.u, 0.001);
  assert.equal(bx.U, 0.002, 'expanded uncertainty is 2 u');
  assert.equal(byKey['gyro.bias_dph.z'].U, 0.004);
  // Not determined: never a zero.
  assert.equal(byKey['gyro.noise.bias_instability_dph'].value, null);
  assert.equal(byKey['gyro.noise.bias_instability_dph'].determined, false);
  assert.equal(byKey['gyro.noise.arw_deg_rth'].value, 0.0005);
  assert.equal(byKey['gyro.noise.arw_deg_rth'].u, null, 'noise terms carry no uncertainty');
  assert.equal(byKey['accel.misalignment_arcsec.xz'].value, null, 'no sigma: not determined');
  assert.equal(byKey['accel.misalignment_arcsec.xz'].U, null);
  assert.equal(byKey['accel.misalignment_arcsec.xy'].U, 1);
  // A group the run determined nothing of is one row, unless a limit applies to one of its members.
  assert.equal(byKey['gyro.delay_us'].collapsed, true);
  assert.equal(byKey['gyro.delay_us'].count, 3);
  assert.equal(byKey['gyro.delay_us.x'], undefined);
  assert.equal(byKey['accel.lever_arm_mm'], undefined);
  assert.equal(byKey['accel.lever_arm_mm.y.x'].value, null);
  assert.equal(byKey['accel.lever_arm_mm.y.x'].pass, false);
  assert.equal(byKey['accel.lever_arm_mm.y.x'].reason, 'not determined by this run');
  // The verdict per coefficient, with its limits.
  assert.equal(bx.pass, false);
  assert.equal(bx.limit, '|value| ≤ 0.05000; u ≤ 0.002000');
  assert.equal(byKey['gyro.bias_dph.y'].pass, true);
  assert.equal(byKey['gyro.bias_dph.y'].limit, '|value| ≤ 0.05000');
  assert.equal(byKey['gyro.bias_dph.z'].pass, null, 'no limit: not judged');
  assert.deepEqual(verdictStatement(verdict, 'PN-1'),
    { status: 'FAIL', text: '2 coefficients outside the acceptance limits of part number PN-1 (limits: limits.json)' });
  assert.equal(verdictStatement({ ...verdict, pass: true, failures: 0 }, 'PN-1').status, 'PASS');
  assert.deepEqual(verdictStatement(null, 'PN-7'), { status: null, text: 'No acceptance limits for part number PN-7' });
  assert.match(verdictStatement(null, '').text, /No part number/);
  // Without a verdict nothing is judged.
  assert.ok(certificateRows(model, null).every((r) => r.pass === null && r.limit === ''));

  // A partial run says why, a complete one nothing.
  assert.equal(partialStatement({ state: 'done', complete: true }), null);
  assert.equal(partialStatement({ state: 'running', complete: false }), null);
  const stopped = partialStatement({ state: 'done', complete: false, progress: 0.594,
    transitions: [{ to: 'running', reason: 'start by alice', t: '2026-01-01T10:00:00Z' },
      { to: 'stopping', reason: 'stop by alice', t: '2026-01-01T14:03:00Z' }] });
  assert.match(stopped, /^stopped at 59 % of the program \(stop by alice, \d\d:\d\d:\d\d\)$/);
  assert.match(partialStatement({ state: 'failed', complete: false, progress: 0.2, error: 'table fault' }), /failed at 20 % .*table fault/);

  // A run started under an operator's override of overdue equipment says who, which (imucald's
  // words) and why; one started without says nothing.
  assert.equal(overrideStatement({ state: 'done', override_overdue: null }), null);
  assert.equal(overrideStatement({ state: 'done' }), null);
  assert.match(overrideStatement({ override_overdue: { by: 'alice', at: '2026-11-28T09:14:02.000Z', reason: 'customer deadline',
    text: 'the rate table (Acme ATS-3, serial T-1) was due for calibration on 2020-01-31' } }),
  /^Started by alice \(2026-11-2\d \d\d:\d\d:02, local time\) although the rate table \(Acme ATS-3, serial T-1\) was due for calibration on 2020-01-31; reason given: customer deadline$/);

  // Reference equipment: simulated said so; real with an overdue instrument marked.
  assert.match(equipmentLines({ simulated: true, devices: 'sim' })[0].text, /Simulated three-axis rate table/);
  const real = equipmentLines({ simulated: false, devices: 'real', reference_equipment: {
    table: { make: 'Acme', model: 'ATS-3', serial: 'T-1', calibration_due: '2020-01-31', calibration_certificate: null, overdue: true },
    chamber: null } });
  assert.equal(real[0].overdue, true);
  assert.match(real[0].text, /Acme ATS-3, serial number T-1; calibration due 2020-01-31 — OVERDUE/);
  assert.equal(real[1].missing, true);
  assert.equal(real.length, 2, 'a certificate issued before the gravity survey was stated gets no line for it');
  // Issue 35: uncertainties and the gravity survey, on certificates issued since.
  const now = equipmentLines({ simulated: false, devices: 'real', gravity: { value_mps2: 9.81912, source: 'configured' },
    reference_equipment: {
      table: { make: 'Acme', model: 'ATS-3', serial: 'T-1', calibration_due: '2027-01-31', calibration_certificate: 'DKD-1',
        uncertainty: '1 arcsec (k=2)', overdue: false },
      chamber: { make: 'ClimaCo', model: 'CC', serial: 'C-1', calibration_due: '2027-01-31', calibration_certificate: null,
        uncertainty: null, overdue: false },
      gravity: { surveyed_by: 'Federal Geodesy Agency', calibration_certificate: 'GS-17', calibration_due: '2026-01-01',
        uncertainty: '1e-06 m/s^2 (1 sigma)', sigma_mps2: 1e-6, overdue: true } } });
  assert.deepEqual(now.map((l) => l.role), ['Rate table', 'Climatic chamber', 'Gravity survey']);
  assert.match(now[0].text, /serial number T-1; calibration due 2027-01-31 \(its certificate DKD-1\); uncertainty 1 arcsec \(k=2\)$/);
  assert.match(now[1].text, /; uncertainty not stated$/);
  assert.equal(now[2].overdue, true);
  assert.match(now[2].text, /^surveyed by Federal Geodesy Agency, certificate GS-17; standard uncertainty of g 1e-06 m\/s\^2 \(1 sigma\); next survey due 2026-01-01 — OVERDUE/);
  const normal = equipmentLines({ simulated: true, devices: 'sim', gravity: { source: 'normal_gravity' }, reference_equipment: { gravity: null } });
  assert.equal(normal.length, 2);
  assert.equal(normal[1].missing, false);
  assert.match(normal[1].text, /not measured/);
  assert.match(gravityStatement({ value_mps2: 9.81912, source: 'configured', sigma_mps2: 1e-6 }), /configured .*; standard uncertainty 1\.0e-6 m\/s²$/);
  assert.match(gravityStatement({ value_mps2: 9.81912, source: 'configured' }), /^9\.8191200 m\/s², configured/);
  assert.match(gravityStatement({ value_mps2: 9.8191, source: 'normal_gravity', latitude_deg: 59.94, height_m: 10 }), /normal gravity formula at latitude 59\.94/);
  const conventions = conventionsText('instrument').join(' ');
  for (const words of ['u = D · S · i + b + n', 'instrument frame', 'right-handed', 'ppm', 'arc seconds'])
    assert.ok(conventions.includes(words), words);
  assert.ok(!conventions.includes('CONVENTIONS.md'), 'stated, not referred to');
});

test('certificate numbers: uncertainties to two significant digits, the estimate to the same decimal place', async () => {
  const { roundedNumbers } = await import('../../web/js/certificate_rows.mjs');
  assert.deepEqual(roundedNumbers({ value: 0.0123456, u: 0.000345, U: 0.00069 }), { value: '0.01235', u: '0.00035', U: '0.00069' });
  assert.deepEqual(roundedNumbers({ value: 12.3456, u: 1.234, U: 2.468 }), { value: '12.3', u: '1.2', U: '2.5' });
  assert.deepEqual(roundedNumbers({ value: -153.7, u: 12.5, U: 25 }), { value: '-154', u: '13', U: '25' });
  // Below six decimals: exponent form, the estimate at u's place, never fewer digits than u's two.
  assert.deepEqual(roundedNumbers({ value: 9.8364e-12, u: 1.3e-11, U: 2.6e-11 }), { value: '1.0e-11', u: '1.3e-11', U: '2.6e-11' });
  assert.deepEqual(roundedNumbers({ value: 3.5e-3, u: 1.2e-9, U: 2.4e-9 }), { value: '3.5000000e-3', u: '1.2e-9', U: '2.4e-9' });
  assert.deepEqual(roundedNumbers({ value: -4.2e-9, u: 3.1e-8, U: 6.2e-8 }), { value: '-0.4e-8', u: '3.1e-8', U: '6.2e-8' });
  // No uncertainty (a noise term): three significant digits; not determined: nothing.
  assert.deepEqual(roundedNumbers({ value: 0.00183361, u: null, U: null }), { value: '0.00183', u: null, U: null });
  assert.deepEqual(roundedNumbers({ value: null, u: null, U: null }), { value: null, u: null, U: null });
});

test('certificate numbers: a row is in one form, fixed or exponent', async () => {
  const { roundedNumbers } = await import('../../web/js/certificate_rows.mjs');
  // u needs exponent form (its second digit below the sixth decimal), so U does too, although it alone would not.
  assert.deepEqual(roundedNumbers({ value: 1.96e-5, u: 5.5e-6, U: 1.1e-5 }), { value: '1.96e-5', u: '5.5e-6', U: '1.1e-5' });
});

test('numbers and times for people: durations rounded once, time ticks with hours and minutes', async () => {
  const { duration, clockTick } = await import('../../web/js/format.mjs');
  assert.equal(duration(119.6), '2 min 00 s', 'never "1 min 60 s"');
  assert.equal(duration(59.7), '1 min 00 s');
  assert.equal(duration(9.96), '10 s');
  assert.equal(duration(4.25), '4.3 s');
  assert.equal(duration(403), '6 min 43 s');
  assert.equal(duration(7199.9), '2 h 00 min');
  assert.equal(duration(-90), '-1 min 30 s');
  const t = new Date(2026, 2, 1, 14, 3, 25).getTime() / 1000;
  assert.equal(clockTick(t, 5), '14:03:25');
  assert.equal(clockTick(t, 300), '14:03');
  assert.equal(clockTick(t, 2 * 86400), '03-01 14:03');
});

// ---- alarms (issue 18, item 1) ----

const alarm = (id, fields = {}) => ({ id, campaign: 1, campaign_name: 'c', severity: 'major', source: 'suspended',
  message: 'chamber out of band', raised: '2026-01-01T10:00:00.000Z', cleared: null, cleared_reason: null,
  acknowledged_by: null, acknowledged: null, ...fields });

test('an alarm is listed while it is active or not acknowledged', () => {
  assert.equal(alarmStatus(alarm(1)), 'active');
  assert.equal(alarmStatus(alarm(1, { acknowledged_by: 'alice', acknowledged: '2026-01-01T10:01:00.000Z' })), 'active-acknowledged');
  assert.equal(alarmStatus(alarm(1, { cleared: '2026-01-01T10:02:00.000Z' })), 'cleared');
  const closed = alarm(1, { cleared: '2026-01-01T10:02:00.000Z', acknowledged_by: 'alice', acknowledged: '2026-01-01T10:03:00.000Z' });
  assert.equal(alarmStatus(closed), 'closed');
  assert.equal(needsAttention(closed), false);
  assert.equal(needsAttention(alarm(1, { cleared: '2026-01-01T10:02:00.000Z' })), true, 'cleared but not acknowledged stays');
});

test('live alarm messages update the list: added, replaced, dropped once closed, newest first', () => {
  let list = [];
  list = applyAlarm(list, alarm(1));
  list = applyAlarm(list, alarm(2, { severity: 'minor', source: 'alarm' }));
  assert.deepEqual(list.map((a) => a.id), [2, 1]);
  const before = list;
  list = applyAlarm(list, alarm(1, { cleared: '2026-01-01T10:02:00.000Z' }));
  assert.equal(before.find((a) => a.id === 1).cleared, null, 'the list given is not changed');
  assert.deepEqual(list.map((a) => [a.id, alarmStatus(a)]), [[2, 'active'], [1, 'cleared']]);
  list = applyAlarm(list, alarm(1, { cleared: '2026-01-01T10:02:00.000Z', acknowledged_by: 'alice', acknowledged: '2026-01-01T10:03:00.000Z' }));
  assert.deepEqual(list.map((a) => a.id), [2]);
  // A message about an alarm already closed (e.g. after a reload) adds nothing.
  list = applyAlarm(list, alarm(0, { cleared: 'x', acknowledged: 'y', acknowledged_by: 'bob' }));
  assert.deepEqual(list.map((a) => a.id), [2]);
});

test('an alarm says whether it is active, and who acknowledged it when', () => {
  assert.equal(alarmStatusText(alarm(1)), 'active, not acknowledged');
  assert.equal(alarmStatusText(alarm(1, { cleared: 'T1' })), 'cleared T1, not acknowledged');
  assert.equal(alarmStatusText(alarm(1, { cleared: 'T1', acknowledged_by: 'alice', acknowledged: 'T2' }), (t) => `<${t}>`),
    'cleared <T1>, acknowledged by alice at <T2>');
  assert.equal(alarmSummary([alarm(1, { cleared: 'T1' })]), '1 alarm to acknowledge');
  assert.equal(alarmSummary([alarm(1), alarm(2, { cleared: 'T1' })]), '2 alarms (1 active), 2 to acknowledge');
  assert.equal(alarmSummary([alarm(1, { acknowledged_by: 'a', acknowledged: 'T' })]), '1 alarm (1 active), all acknowledged');
});

test('the recording as plots: x in program seconds, each channel its maximum and minimum', async () => {
  const { chartData } = await import('../../web/js/recording_plots.mjs');
  const series = { t_s: [0, 1, 2], table_deg: { outer: { min: [0, 1, null], max: [0.5, 2, null] }, inner: { min: [5, 5, 5], max: [6, 6, 6] } } };
  const { labels, data } = chartData(series, 'table_deg', ['outer', 'middle', 'inner']);
  assert.deepEqual(labels, ['outer max', 'outer min', 'inner max', 'inner min'], 'channels the run lacks are left out');
  assert.deepEqual(data, [[0, 1, 2], [0.5, 2, null], [0, 1, null], [6, 6, 6], [5, 5, 5]]);
  assert.deepEqual(chartData(series, 'temperature_C', ['chamber']).labels, []);
});

test('a program edited and edited back is the built-in program again (canonical JSON)', async () => {
  const { canonical } = await import('../../web/js/program_edit.mjs');
  const a = { name: 'p', segments: [{ type: 'rate', axis: 'outer', rate_dps: 20, revolutions: 2 }] };
  const b = { segments: [{ revolutions: 2, rate_dps: 20, type: 'rate', axis: 'outer' }], name: 'p' };
  assert.equal(canonical(a), canonical(b));
  assert.notEqual(canonical(a), canonical({ ...a, segments: [{ ...a.segments[0], rate_dps: 21 }] }));
});

test('positions are edited one per line and read back either way', async () => {
  const { formatValue, parseField, SEGMENT_TYPES } = await import('../../web/js/program_edit.mjs');
  const field = SEGMENT_TYPES.positions.find((x) => x.key === 'positions_deg');
  const twelve = Array.from({ length: 12 }, (_, k) => [30 * k, 0, 0]);
  const text = formatValue(field, twelve);
  assert.equal(text.split('\n').length, 12, 'one line per position');
  assert.deepEqual(parseField(field, text).value, twelve);
});

test('the builder\'s prediction with stage 1\'s budget: the dominant source and the bench it needs (issue 34)', async () => {
  const { dominantSources, benchRequirements } = await import('../../web/js/plan.mjs');
  const { sourceName } = await import('../../web/js/budget.mjs');
  const prediction = { stages: { direct: {
    budget: { 'gyro.bias_dph.x': { combined: 0.005, dominant: 'table.middle_axis_arcsec',
      contributions: { type_a: 0.003, 'table.middle_axis_arcsec': 0.004 } } },
    requirements: { limits: { 'gyro.bias_dph': 0.002 }, sources: [
      { source: 'table.middle_axis_arcsec', sigma: 1, alone: { max_factor: 0.0296, max_sigma: 0.0296, limiting: 'gyro.bias_dph.x' },
        with_others: { max_factor: 0, max_sigma: 0, limiting: 'gyro.bias_dph.x' } }],
    whole_table: { max_factor: 0.5, limiting: 'gyro.bias_dph.x' } } } } };
  const d = dominantSources(prediction).get('gyro.bias_dph.x');
  assert.equal(d.source, 'table.middle_axis_arcsec');
  assert.ok(Math.abs(d.share - 0.64) < 1e-12);
  assert.equal(sourceName(d.source), 'Table: middle axis');
  assert.equal(sourceName('type_a'), 'Measurement (type A)');
  assert.equal(sourceName('start_model.accel.k2_ug_per_g2'), 'Start model: accel.k2_ug_per_g2');
  const r = benchRequirements(prediction);
  assert.equal(r.sources[0].alone.maxSigma, 0.0296);
  assert.equal(r.sources[0].withOthers.maxFactor, 0);
  assert.equal(r.wholeTable.maxFactor, 0.5);
  assert.equal(benchRequirements({ stages: { navigation: {} } }), null);
  // Stage 3's, asked for by its stage's key.
  const stage3 = { stages: { navigation: prediction.stages.direct } };
  assert.equal(benchRequirements(stage3, 'navigation').sources[0].alone.maxSigma, 0.0296);
  assert.equal(dominantSources(stage3, 'navigation').get('gyro.bias_dph.x').source, 'table.middle_axis_arcsec');
  assert.equal(dominantSources(stage3).size, 0);
  assert.equal(dominantSources({}).size, 0);
});

test('certificate budget: one column per source, type A first, each coefficient\'s contributions and its dominant source', async () => {
  const { budgetTable } = await import('../../web/js/budget.mjs');
  const model = {
    gyro: { bias_dph: [0.01, 0, 0] },
    sigma: { gyro: { bias_dph: [0.005, 0.001, 0] }, accel: { scale_ppm: [30, 0, 0] } },
    budget: {
      'site.gravity_mps2': { gyro: { bias_dph: [0, 0, 0] }, accel: { scale_ppm: [30, 0, 0] } },
      'table.middle_axis_arcsec': { gyro: { bias_dph: [0.004, 0, 0] } },
      type_a: { gyro: { bias_dph: [0.003, 0.001, 0] }, accel: { scale_ppm: [0.2, 0, 0] } },
      'table.inner_axis_arcsec': { gyro: { bias_dph: [0, 0, 0] } },
    },
  };
  const t = budgetTable(model);
  assert.deepEqual(t.sources, ['type_a', 'table.middle_axis_arcsec', 'site.gravity_mps2'], 'a source of zeros only is left out');
  assert.deepEqual(t.rows.map((r) => r.key), ['gyro.bias_dph.x', 'gyro.bias_dph.y', 'accel.scale_ppm.x']);
  assert.equal(t.rows[0].dominant, 'table.middle_axis_arcsec');
  assert.equal(t.rows[0].u, 0.005);
  assert.deepEqual(t.rows[1].contributions, { type_a: 0.001 });
  assert.equal(t.rows[2].dominant, 'site.gravity_mps2');
  assert.deepEqual(budgetTable({ sigma: {} }), { sources: [], rows: [] });
});

test('every list tells done, stopped, partial, failed and aborted apart (issue 35)', () => {
  const o = (c) => runOutcome(c).outcome;
  assert.equal(o({ state: 'done', complete: true }), 'done');
  assert.equal(o({ state: 'done' }), 'done', 'a run stored before `complete` existed ran to its end');
  assert.equal(o({ state: 'done', complete: false }), 'stopped');
  assert.equal(o({ state: 'done', complete: false, accepted: { reason: 'r' } }), 'partial');
  assert.equal(o({ state: 'failed', complete: false }), 'failed');
  assert.equal(o({ state: 'failed', complete: false, accepted: { reason: 'r' } }), 'partial');
  assert.equal(o({ state: 'aborted', complete: false }), 'aborted');
  assert.equal(o({ state: 'aborted', complete: false, accepted: { reason: 'r' } }), 'partial');
  assert.equal(o({ state: 'running' }), 'running');
  assert.match(runOutcome({ state: 'failed', error: 'the table stopped answering' }).title, /table stopped/);
  assert.match(runOutcome({ state: 'done', complete: false, accepted: { reason: 'first two cycles' } }).title, /first two cycles/);
});

test('reference equipment: the live page shows imucald\'s warnings a week ahead and the start asks for an override', async () => {
  const { equipmentWarnings, overdueStartQuestion } = await import('../../web/js/equipment.mjs');
  assert.equal(equipmentWarnings(undefined), null);
  assert.equal(equipmentWarnings({ table: null, chamber: null, gravity: null, banner: null }), null);
  // The words are imucald's (GET /api/status reference_equipment: each instrument's text, the
  // banner's sentence); the page picks those due soon or overdue and puts the overdue first.
  const tableText = 'The rate table (Acme Motion ATS-3, serial T-0815) is due for calibration on 2026-12-01 (in 3 days).';
  const gravityText = 'The gravity survey (by NGS, certificate G-1) was due for a new survey on 2026-11-01 (27 days ago).';
  const banner = 'No campaign starts while reference equipment is past its due date unless an operator overrides it.';
  const warnings = equipmentWarnings({
    table: { calibration_due: '2026-12-01', due_in_days: 3, due_soon: true, overdue: false, text: tableText },
    chamber: { calibration_due: '2027-06-01', due_in_days: 185, due_soon: false, overdue: false, text: 'The climatic chamber ...' },
    gravity: { calibration_due: '2026-11-01', due_in_days: -27, due_soon: false, overdue: true, text: gravityText },
    banner,
  });
  assert.deepEqual(warnings.lines.map((w) => [w.instrument, w.overdue, w.text]), [['gravity', true, gravityText], ['table', false, tableText]],
    'overdue first, the far one not at all, in imucald\'s words');
  assert.equal(warnings.overdue, true);
  assert.equal(warnings.sentence, banner);
  assert.equal(equipmentWarnings({ table: { due_in_days: 0, due_soon: true, overdue: false, text: tableText }, banner }).overdue, false);

  assert.equal(overdueStartQuestion({ error: 'campaign 7 was already started', state: 'done' }), null);
  const overdueText = 'The rate table (Acme Motion ATS-3, serial T-0815) was due for calibration on 2020-01-31 (2493 days ago).';
  const question = overdueStartQuestion({ error: '...', state: 'created', overdue: [
    { instrument: 'table', identity: 'Acme Motion ATS-3, serial T-0815', serial: 'T-0815', certificate: 'DKD-1', calibration_due: '2020-01-31',
      text: overdueText }] });
  assert.equal(question[0], overdueText);
  assert.match(question[1], /audit trail/);
});

test('the simulated truth in the builder: the names offered, nav-grade by default, an uploaded file checked', async () => {
  const { truthChoices, defaultTruth, parseTruthFile, truthLabel } = await import('../../web/js/truths.mjs');
  const offered = [{ name: 'ideal', description: 'error-free', builtin: true }, { name: 'nav-grade', description: 'navigation grade', builtin: true },
    { name: 'lab-unit', description: 'the model lab-unit.json of the truths folder', builtin: false }];
  assert.deepEqual(truthChoices(offered).map((t) => t.name), ['ideal', 'nav-grade', 'lab-unit']);
  assert.deepEqual(truthChoices(undefined).map((t) => t.name), ['ideal'], 'an older imucald: ideal only');
  assert.equal(defaultTruth(offered), 'nav-grade', 'a realistic unit with noise by default');
  assert.equal(defaultTruth([{ name: 'ideal' }]), 'ideal');
  const model = parseTruthFile('{"format": "imucal-imu-model/1", "frame": "instrument", "gyro": {"bias_dph": [0.1, 0, 0]}}', 'unit.json');
  assert.deepEqual(model.model.gyro.bias_dph, [0.1, 0, 0]);
  assert.match(parseTruthFile('{"format": "imucal-imu-model/1", "frame": "body"}', 'b.json').error, /b\.json is in the body frame/);
  assert.match(parseTruthFile('{"format": "x"}', 'x.json').error, /x\.json is not an IMU model/);
  assert.match(parseTruthFile('not json', 'n.json').error, /n\.json is not JSON/);
  assert.match(parseTruthFile('[1]', 'a.json').error, /not a JSON object/);
  assert.match(parseTruthFile('', 'e.json').error, /empty/);
  assert.match(parseTruthFile('{}' + ' '.repeat(1 << 20), 'big.json').error, /larger than 1 MiB/);
  assert.equal(truthLabel('nav-grade'), 'nav-grade');
  assert.match(truthLabel({ format: 'imucal-imu-model/1' }), /uploaded/);
});

test('the live store keeps a finished run (its plots, convergence and final state) until another starts', async () => {
  const realFetch = globalThis.fetch;
  // /progress of a run: none here (the live messages fill the plots).
  globalThis.fetch = async () => ({ ok: false, status: 404, headers: { get: () => 'application/json' }, json: async () => ({ error: 'none' }), text: async () => '{}' });
  try {
    const { LiveStore } = await import('../../web/js/live.mjs');
    const store = new LiveStore();
    const at = (s) => new Date(Date.UTC(2026, 10, 28, 1, 0, s)).toISOString();
    const running = (s) => ({ type: 'telemetry', t: at(s), run: { id: 7, name: 'full', state: 'running' }, table: { angle_deg: [s, 0, 0], rate_dps: [0, 0, 0] },
      imu: { frame_rate_hz: 100 }, estimators: { stage3: { program_time_s: s, estimates: { 'gyro.bias_dph.x': [0.04, 0.001] } } } });
    for (let s = 0; s < 5; s++) store.ingest(running(s));
    store.ingest({ type: 'event', campaign: 7, kind: 'transition', from: 'running', to: 'done' });
    for (let s = 5; s < 9; s++) store.ingest({ type: 'telemetry', t: at(s), run: null, table: { angle_deg: [99, 0, 0], rate_dps: [0, 0, 0] }, imu: { frame_rate_hz: 0 } });
    assert.deepEqual(store.finished, { id: 7, name: 'full', state: 'done' }, 'the finished run, its final state');
    assert.equal(store.runId, null);
    const [times, x] = store.angles.view(Infinity);
    assert.equal(times.length, 5, 'the run\'s samples kept, the idle bench not drawn over them');
    assert.equal(x[4], 4);
    assert.equal(store.frameRate.view(Infinity)[0].length, 5, 'the frame-rate plot keeps the run (not blank)');
    assert.ok(store.estimators.get('stage3').coefficients.has('gyro.bias_dph.x'), 'and its convergence');
    // The next run starts empty and forgets the finished one.
    store.ingest({ type: 'telemetry', t: at(20), run: { id: 8, name: 'next', state: 'running' }, table: { angle_deg: [1, 0, 0], rate_dps: [0, 0, 0] } });
    assert.equal(store.finished, null);
    assert.equal(store.angles.view(Infinity)[0].length, 1);
    assert.equal(store.estimators.size, 0);
  } finally {
    globalThis.fetch = realFetch;
  }
});

test('the limits form: a file into rows and back, every problem beside its row (issue 36, item 5)', async () => {
  const { limitsToForm, formToLimits, emptyRow, locateServerProblem } = await import('../../web/js/limits_form.mjs');
  const file = { format: 'imucal-limits/1', comment: 'lab limits', part_numbers: {
    'FOG-3A': { 'gyro.bias_dph': { max_abs: 0.05, max_sigma: 0.001 }, 'gyro.noise.arw_deg_rth': { max_abs: 0.001 } } } };
  const form = limitsToForm(file);
  assert.deepEqual(form.parts[0].rows[0], { key: 'gyro.bias_dph', maxAbs: '0.05', maxSigma: '0.001' });
  assert.deepEqual(form.parts[0].rows[1], { key: 'gyro.noise.arw_deg_rth', maxAbs: '0.001', maxSigma: '' });
  // Unchanged, the form stands for the same file.
  assert.deepEqual(formToLimits(form), { doc: file, problems: [] });
  // No file yet: no part numbers, and the form's document is an empty limits file.
  assert.deepEqual(formToLimits(limitsToForm({ format: 'imucal-limits/1' })).doc, { format: 'imucal-limits/1', part_numbers: {} });

  form.parts[0].rows[0].maxSigma = '-1';
  form.parts[0].rows[1].maxSigma = '0.1';
  form.parts[0].rows.push(emptyRow(), { key: 'gyro.bias_dph', maxAbs: '1e-2', maxSigma: 'abc' }, { key: 'gyro bias', maxAbs: '1', maxSigma: '' });
  form.parts.push({ partNumber: ' FOG-3A ', rows: [] });
  const r = formToLimits(form);
  assert.equal(r.doc, null, 'nothing half-checked is sent');
  const at = (part, row, field) => r.problems.filter((q) => q.part === part && q.row === row && q.field === field).map((q) => q.message);
  assert.deepEqual(at(0, 0, 'maxSigma'), ['Must be a positive number, in the key\'s unit.']);
  assert.deepEqual(at(0, 1, 'maxSigma'), ['A noise term carries no σ: limit its value only.']);
  assert.deepEqual(at(0, 2, 'key'), ['Choose the coefficient (or group) this limit is for.']);
  assert.deepEqual(at(0, 2, null), ['Give a limit on |value|, on σ, or both.']);
  assert.deepEqual(at(0, 3, 'key'), ['gyro.bias_dph has a limit already in this part number.']);
  assert.deepEqual(at(0, 3, 'maxSigma'), ['not a number.']);
  assert.equal(at(0, 4, 'key').length, 1, 'a key with a space is not a coefficient name');
  assert.deepEqual(at(1, null, 'partNumber'), ['Part number FOG-3A is listed twice.']);
  assert.equal(r.problems.length, 8);

  // imucald's refusal names the part number and key: found back in the form.
  const located = limitsToForm({ part_numbers: { 'PN-1': { 'gyro.bias_dph': { max_abs: 1 }, 'gyro.bias': { max_abs: 1 } } } });
  assert.deepEqual(locateServerProblem('limits.part_numbers["PN-1"]["gyro.bias"]: no coefficient of the model is named so', located), { part: 0, row: 1 });
  assert.deepEqual(locateServerProblem('limits.part_numbers["PN-1"] must be an object of coefficient keys', located), { part: 0, row: null });
  assert.equal(locateServerProblem('limits.part_numbers["PN-2"]["gyro.bias"]: ...', located), null);
  assert.equal(locateServerProblem('limits.format must be "imucal-limits/1"', located), null);
});

test('a duration never reads "0.0 s" when it is not zero (issue 36, item 6: ×100000)', async () => {
  const { duration } = await import('../../web/js/format.mjs');
  assert.equal(duration(507 / 100000), '5.1 ms');
  assert.equal(duration(0.05), '50 ms');
  assert.equal(duration(2e-5), 'under 0.1 ms');
  assert.equal(duration(0), '0.0 s');
  assert.equal(duration(0.2), '0.2 s');
  assert.equal(duration(119.6), '2 min 00 s');
  const { fixed } = await import('../../web/js/format.mjs');
  assert.equal(fixed(-0.0001, 3), '0.000');
  assert.equal(fixed(-0.0006, 3), '-0.001');
});

test('axis ticks read differently at one scale, the power of ten beside the unit (issue 36, item 7)', async () => {
  const { axisTicks, axisUnit } = await import('../../web/js/format.mjs');
  // A convergence plot of a bias near 1e-4 °/h: once "1.0e-4" three times, or a lone "0".
  assert.deepEqual(axisTicks([1.02e-4, 1.04e-4, 1.06e-4], 2e-6), { labels: ['102', '104', '106'], exponent: -6 });
  assert.equal(axisUnit('°/h', -6), '×10⁻⁶ °/h');
  assert.deepEqual(axisTicks([-2e-5, 0, 2e-5], 1e-5).labels, ['-20', '0', '20']);
  // Ordinary magnitudes as they are, with the spacing's decimals; no "-0".
  assert.deepEqual(axisTicks([-0.5, 0, 0.5, 1], 0.5), { labels: ['-0.5', '0.0', '0.5', '1.0'], exponent: 0 });
  assert.deepEqual(axisTicks([0.1, 0.2, 0.30000000000000004], 0.1).labels, ['0.1', '0.2', '0.3']);
  assert.deepEqual(axisTicks([0, 500, 1000], 500).labels, ['0', '500', '1000']);
  assert.deepEqual(axisTicks([1, 2, 3], 1).labels, ['1', '2', '3']);
  assert.deepEqual(axisTicks([2e6, 4e6], 2e6), { labels: ['2', '4'], exponent: 6 });
  assert.equal(axisUnit('m', 0), 'm');
  assert.equal(axisUnit(undefined, 3), '×10³');
});

test('a paused run says who paused it and how it goes on (issue 36, item 8)', async () => {
  const { pauseNote } = await import('../../web/js/outcome.mjs');
  const transitions = [
    { t: 'T1', from: 'queued', to: 'running', reason: 'start by operator' },
    { t: 'T2', from: 'running', to: 'pausing', reason: 'pause by alice: cable check' },
    { t: 'T3', from: 'pausing', to: 'paused', reason: 'table at rest' },
  ];
  const n = pauseNote(transitions, (t) => `at-${t}`);
  assert.equal(n.by, 'alice');
  assert.equal(n.why, 'cable check');
  assert.match(n.text, /^Paused by alice at at-T2 \(cable check\)\. .*Resume/);
  // The newest pause counts; without transitions (not loaded yet) it still says how to go on.
  assert.equal(pauseNote([...transitions, { t: 'T4', to: 'running', reason: 'resume by bob' }, { t: 'T5', to: 'pausing', reason: 'pause by bob' }]).by, 'bob');
  assert.match(pauseNote(null).text, /^Paused\. .*presses Resume/);
});

test('the first screen names the bench and its devices (issue 36, item 9)', async () => {
  const { benchSummary } = await import('../../web/js/bench.mjs');
  const idle = { run: null, table: { connected: true, homed: true }, chamber: { connected: true, temperature_C: 25.04 },
    imu: { connected: true, frame_rate_hz: 50 } };
  const sim = benchSummary({ devices: 'sim', site: { name: 'lab 1' } }, idle);
  assert.equal(sim.simulated, true);
  assert.equal(sim.title, 'Simulated bench');
  assert.equal(sim.site, 'lab 1');
  assert.deepEqual(sim.devices.map((d) => `${d.name}: ${d.state}, ${d.text}`),
    ['Rate table: ok, connected, homed', 'Chamber: ok, connected, 25.0 °C', 'IMU: ok, connected']);
  // A real bench with its chamber down; before the first telemetry nothing is claimed.
  const real = benchSummary({ devices: 'real' }, { ...idle, chamber: { connected: false }, run: { id: 1 } });
  assert.equal(real.simulated, false);
  assert.match(real.text, /moves the table/);
  assert.deepEqual(real.devices.map((d) => d.text), ['connected, homed', 'not connected', 'connected, 50.0 frames/s']);
  const unhomed = benchSummary({ devices: 'sim' }, { ...idle, table: { connected: true, homed: false } }).devices[0];
  assert.deepEqual([unhomed.state, unhomed.text], ['warn', 'connected, not homed yet (a run homes it first)']);
  assert.deepEqual(benchSummary({ devices: 'sim-wire' }, null).devices.map((d) => d.state), ['unknown', 'unknown', 'unknown']);
});
