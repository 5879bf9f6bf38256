// One part number's block of the acceptance limits form: its number, a row per coefficient or
// group key with the largest |value| and the largest 1σ, and the buttons that add and remove.
// Every edit is written into the form's objects (p, its rows) and reported through edited().
import { h } from '../../format.mjs';
import { groups, coefficientName, unitOf } from '../../coefficients.mjs';
import { schema } from '../../schema.mjs';
import { emptyRow } from '../../limits_form.mjs';

// The example the hint and an empty key show: imucald's first coefficient, and its group.
export function example() {
  return schema().coefficients[0] || { key: '', group: '' };
}

// A coefficient key's name and unit for people, or what is wrong with it (coefficients.mjs).
function describeKey(key) {
  const k = key.trim();
  if (!k) return '';
  const unit = unitOf(k);
  const group = groups().find((g) => g.key === k);
  const name = group ? `${group.title}, every axis` : coefficientName(k);
  return `${name === k ? '' : name}${unit ? `${name === k ? '' : ', '}in ${unit}` : ''}`;
}

/** Part pi's fieldset. edited(structural) after a change (structural: the form is drawn again),
 *  removePart() takes the part out, focus(id) focuses an input once the form is drawn again. */
export function limitsPart(p, pi, { edited, removePart, focus }) {
  const partInput = h('input', { type: 'text', id: `limits-part-${pi}-number`, value: p.partNumber, class: 'part-number', 'aria-label': 'part number' });
  partInput.addEventListener('input', () => { p.partNumber = partInput.value; p.touched = true; edited(); });
  const rows = h('tbody', {});
  p.rows.forEach((r, ri) => rows.append(...limitRow(p, pi, r, ri, edited)));
  const add = h('button', { type: 'button', id: `limits-part-${pi}-add` }, 'Add a limit');
  add.addEventListener('click', () => { p.rows.push(emptyRow()); edited(true); focus(`limits-${pi}-${p.rows.length - 1}-key`); });
  const remove = h('button', { type: 'button', class: 'danger-text', id: `limits-part-${pi}-remove` }, 'Remove part number');
  remove.addEventListener('click', removePart);
  return h('fieldset', { class: 'limits-part', id: `limits-part-${pi}` },
    h('div', { class: 'limits-part-head' }, h('label', { for: partInput.id }, 'Part number'), partInput, h('span', { class: 'spacer' }), remove),
    h('ul', { class: 'segment-problems', id: `limits-part-${pi}-error`, role: 'alert' }),
    h('table', { class: 'list compact limits-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient or group'), h('th', {}, 'Largest |value|'), h('th', {}, 'Largest 1σ'), h('th', {}))),
      rows),
    p.rows.length ? null : h('p', { class: 'muted' }, 'No limits for this part number yet.'),
    h('div', { class: 'actions' }, add));
}

// A limit's row and the row under it where its problems show.
function limitRow(p, pi, r, ri, edited) {
  const id = `limits-${pi}-${ri}`;
  const key = h('input', { type: 'text', id: `${id}-key`, value: r.key, list: 'limit-keys', class: 'limit-key', 'aria-label': 'coefficient or group', placeholder: `e.g. ${example().key}` });
  const name = h('span', { class: 'hint limit-name', id: `${id}-name` }, describeKey(r.key));
  const bound = (field, label) => {
    const el = h('input', { type: 'text', inputmode: 'decimal', id: `${id}-${field}`, value: r[field], class: 'short', 'aria-label': label });
    el.addEventListener('input', () => { r[field] = el.value; r.touched = true; edited(); });
    return el;
  };
  key.addEventListener('input', () => { r.key = key.value; r.touched = true; name.textContent = describeKey(r.key); edited(); });
  const remove = h('button', { type: 'button', class: 'icon danger-text', id: `${id}-remove`, title: 'Remove this limit', 'aria-label': 'remove this limit' }, '×');
  remove.addEventListener('click', () => { p.rows.splice(ri, 1); p.touched = true; edited(true); });
  return [h('tr', { class: 'limit-row', id, dataset: { key: r.key } },
    h('td', {}, key, name), h('td', {}, bound('maxAbs', 'largest |value|')), h('td', {}, bound('maxSigma', 'largest 1σ')),
    h('td', { class: 'row-actions' }, remove)),
  h('tr', { class: 'limit-problems' }, h('td', { colspan: 4 }, h('ul', { class: 'segment-problems', id: `${id}-error`, role: 'alert' })))];
}
