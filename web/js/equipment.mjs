// The reference equipment's due dates for a person (issue 35): the live page's warning from
// GET /api/status `reference_equipment` (each instrument judged today by imucald, with imucald's
// sentence for it in `text`, and the banner's closing sentence in `banner`), and the question the
// command bar asks when a start is refused for overdue equipment (409 with `overdue`, each with
// its `text`). The rule and the words are the daemon's (daemon/production/reference_equipment.hpp);
// this only picks and orders them. Pure functions of the daemon's replies, without the DOM, so
// that Node tests them (tests/browser/unit.test.mjs).

const ORDER = ['table', 'chamber', 'gravity'];

/**
 * The banner of the live page: {lines: [{instrument, overdue, text}], overdue, sentence}, overdue
 * ones first, for every instrument imucald says is overdue or due within a week; null when none
 * is (or no equipment is configured). `sentence`: what follows for a start (imucald's `banner`).
 */
export function equipmentWarnings(equipment) {
  const lines = [];
  for (const key of ORDER) {
    const i = equipment?.[key];
    if (!i || !(i.overdue || i.due_soon)) continue;
    lines.push({ instrument: key, overdue: Boolean(i.overdue), text: i.text });
  }
  if (!lines.length) return null;
  lines.sort((a, b) => Number(b.overdue) - Number(a.overdue));
  return { lines, overdue: lines.some((l) => l.overdue), sentence: equipment.banner || '' };
}

/**
 * What the start's 409 for overdue equipment said (its `overdue` list), as the lines of the
 * override dialog; null when the refusal was for something else.
 */
export function overdueStartQuestion(body) {
  const list = Array.isArray(body?.overdue) ? body.overdue : [];
  if (!list.length) return null;
  return [
    ...list.map((o) => o.text),
    'imucald did not start the campaign. Start it anyway only if the results are still sound; say why. ' +
      'Your name and reason are kept in the audit trail and with the run, and the run\'s certificate states them.',
  ];
}
