// The reference equipment's due dates in words (issue 35): the live page's warning from
// GET /api/status `reference_equipment` (each instrument judged today by imucald: due_in_days,
// due_soon, overdue; the rule is the daemon's, not repeated here), and the question the command
// bar asks when a start is refused for overdue equipment (409 with `overdue`). Pure functions of
// the daemon's replies, without the DOM, so that Node tests them (tests/browser/unit.test.mjs).

const TITLES = { table: 'rate table', chamber: 'climatic chamber', gravity: 'gravity survey' };
const ORDER = ['table', 'chamber', 'gravity'];

/** "the rate table Acme Motion ATS-3 (serial T-0815)", "the gravity survey by NGS (certificate G-1)". */
export function instrumentName(key, i) {
  if (key === 'gravity') return `the gravity survey by ${i.surveyed_by} (certificate ${i.calibration_certificate})`;
  return `the ${TITLES[key] || key} ${i.make} ${i.model} (serial ${i.serial})`;
}

const days = (n) => `${n} day${n === 1 ? '' : 's'}`;

/**
 * The warnings for the live page: [{instrument, overdue, text}], overdue ones first, for every
 * instrument imucald says is overdue or due within a week; [] when none is (or no equipment is
 * configured).
 */
export function equipmentWarnings(equipment) {
  const out = [];
  for (const key of ORDER) {
    const i = equipment?.[key];
    if (!i || !(i.overdue || i.due_soon)) continue;
    const what = key === 'gravity' ? 'a new survey' : 'calibration';
    const name = instrumentName(key, i);
    const n = i.due_in_days;
    let text;
    if (i.overdue) {
      text = `${name[0].toUpperCase()}${name.slice(1)} was due for ${what} on ${i.calibration_due} (${days(-n)} ago): ` +
        'a campaign starts only when an operator overrides this with a reason, which the audit trail keeps.';
    } else {
      const when = n === 0 ? 'today' : n === 1 ? 'tomorrow' : `in ${days(n)}`;
      text = `${name[0].toUpperCase()}${name.slice(1)} is due for ${what} on ${i.calibration_due} (${when}); ` +
        'after that date no campaign starts without an operator\'s override.';
    }
    out.push({ instrument: key, overdue: Boolean(i.overdue), text });
  }
  return out.sort((a, b) => Number(b.overdue) - Number(a.overdue));
}

/**
 * What the start's 409 for overdue equipment said (its `overdue` list), as the lines of the
 * override dialog; null when the refusal was for something else.
 */
export function overdueStartQuestion(body) {
  const list = Array.isArray(body?.overdue) ? body.overdue : [];
  if (!list.length) return null;
  return [
    ...list.map((o) => `The ${TITLES[o.instrument] || o.instrument} (${o.identity}) was due for ` +
      `${o.instrument === 'gravity' ? 'a new survey' : 'calibration'} on ${o.calibration_due}.`),
    'imucald did not start the campaign. Start it anyway only if the results are still sound; say why. ' +
      'Your name and reason are kept in the audit trail and with the run.',
  ];
}
