// The acceptance limits file (imucal-limits/1, docs/api.md "Acceptance limits") as the rows of a
// form (issue 36, item 5): one block per part number, one row per coefficient key with its two
// bounds. No DOM. The page checks what it can see for itself (numbers, a bound per row, no sigma
// for a noise term, no key or part number twice); which coefficient names exist is imucald's to
// judge (its parser knows every name a model can carry), and its 400 names the part number and
// key, which locateServerProblem() turns back into a row of the form.
import { parseNumber } from './program_edit.mjs';
import { schema } from './schema.mjs';

/**
 * A noise term carries no sigma: a limit on it is max_abs only. imucald's parser refuses a sigma
 * limit on a key holding ".noise." (is_noise in daemon/production/acceptance.cpp), the rule
 * coefficients.mjs's determined() follows too.
 */
export function isNoiseKey(key) {
  return key.includes('.noise.');
}

function boundText(v) {
  return typeof v === 'number' && Number.isFinite(v) ? String(v) : '';
}

/**
 * The form's state from a limits document as GET /api/limits returns it:
 * {comment, parts: [{partNumber, rows: [{key, maxAbs, maxSigma}]}]}, the bounds as the text the
 * inputs hold ('' for none).
 */
export function limitsToForm(doc) {
  const parts = Object.entries(doc?.part_numbers || {}).map(([partNumber, entries]) => ({
    partNumber,
    rows: Object.entries(entries || {}).map(([key, spec]) => ({
      key, maxAbs: boundText(spec?.max_abs), maxSigma: boundText(spec?.max_sigma),
    })),
  }));
  return { comment: doc?.comment, parts };
}

// The examples a refused key's message gives: imucald's first coefficient and its group.
function badKeyMessage() {
  const c = schema().coefficients[0];
  return c ? `A key is a coefficient's name such as ${c.key}, or a group such as ${c.group}.` : 'A key is a coefficient\'s name or a group.';
}

/** An empty row to add to a part number (its key chosen by the operator). */
export function emptyRow() {
  return { key: '', maxAbs: '', maxSigma: '' };
}

/**
 * The limits document the form stands for, and every problem the page can see, each located:
 * {part, row, field, message}; `row` null for the part number itself, `field` the input at fault
 * ('partNumber', 'key', 'maxAbs', 'maxSigma') or null for the row as a whole. `doc` is null when
 * there is a problem: nothing half-checked is sent.
 */
export function formToLimits(form) {
  const problems = [];
  const partNumbers = {};
  const seenParts = new Set();
  (form.parts || []).forEach((p, pi) => {
    const partNumber = (p.partNumber || '').trim();
    if (!partNumber) problems.push({ part: pi, row: null, field: 'partNumber', message: 'A part number is needed.' });
    else if (seenParts.has(partNumber))
      problems.push({ part: pi, row: null, field: 'partNumber', message: `Part number ${partNumber} is listed twice.` });
    seenParts.add(partNumber);
    const entries = {};
    const seenKeys = new Set();
    (p.rows || []).forEach((r, ri) => {
      const at = (field, message) => problems.push({ part: pi, row: ri, field, message });
      const key = (r.key || '').trim();
      if (!key) at('key', 'Choose the coefficient (or group) this limit is for.');
      else if (!/^(gyro|accel)(\.[A-Za-z0-9_]+)*$/.test(key))
        at('key', badKeyMessage());
      else if (seenKeys.has(key)) at('key', `${key} has a limit already in this part number.`);
      seenKeys.add(key);
      const spec = {};
      for (const [field, name] of [['maxAbs', 'max_abs'], ['maxSigma', 'max_sigma']]) {
        const parsed = parseNumber(String(r[field] ?? ''));
        if (parsed.empty) continue;
        if (parsed.error) at(field, `${parsed.error}.`);
        else if (!(parsed.value > 0)) at(field, 'Must be a positive number, in the key\'s unit.');
        else spec[name] = parsed.value;
      }
      const hasAbs = String(r.maxAbs ?? '').trim() !== '';
      const hasSigma = String(r.maxSigma ?? '').trim() !== '';
      if (!hasAbs && !hasSigma) at(null, 'Give a limit on |value|, on σ, or both.');
      if (hasSigma && isNoiseKey(key)) at('maxSigma', 'A noise term carries no σ: limit its value only.');
      entries[key] = spec;
    });
    if (partNumber) partNumbers[partNumber] = entries;
  });
  if (problems.length) return { doc: null, problems };
  const doc = { format: 'imucal-limits/1', part_numbers: partNumbers };
  if (form.comment !== undefined) doc.comment = form.comment;
  return { doc, problems };
}

// imucald's parser names what it refuses as limits.part_numbers["PN"]["key"] (core/json_reader,
// daemon/production/acceptance.cpp).
const SERVER_AT = /part_numbers\["((?:[^"\\]|\\.)*)"\](?:\["((?:[^"\\]|\\.)*)"\])?/;

/**
 * Where in the form imucald's refusal points: {part, row} (row null for the part number as a
 * whole), or null when it names no part number the form has.
 */
export function locateServerProblem(message, form) {
  const m = SERVER_AT.exec(message || '');
  if (!m) return null;
  const part = (form.parts || []).findIndex((p) => (p.partNumber || '').trim() === m[1]);
  if (part < 0) return null;
  if (m[2] === undefined) return { part, row: null };
  const row = form.parts[part].rows.findIndex((r) => (r.key || '').trim() === m[2]);
  return { part, row: row < 0 ? null : row };
}
