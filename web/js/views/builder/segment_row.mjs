// One segment of the builder's program table: its name, type and parameters (checked as typed:
// a number where a number belongs, the keys its type requires), its program time once imucald
// has checked it, its problems, and the buttons that move, copy and delete it.
import { h } from '../../format.mjs';
import { SEGMENT_TYPES, NEW_SEGMENT, AXIS_NAMES, parseField, formatValue } from '../../program_edit.mjs';
import { titled } from './form.mjs';

/** A name for a new segment that no other has: base, else base-2, base-3... */
export function uniqueName(segments, base) {
  let name = base, n = 2;
  while (segments.some((s) => s.name === name)) name = `${base}-${n++}`;
  return name;
}

/** Segment i's row. form: setError(el, message, id), dropErrors(prefix), modified() after an
 *  edit; redraw() draws the table again (after a move, copy, delete or a new type). */
export function segmentRow(state, seg, i, { form, redraw }) {
  const segments = state.draft.program.segments;
  const type = seg.type;
  const fields = SEGMENT_TYPES[type] || [];
  const nameInput = titled(h('input', { type: 'text', id: `seg-${i}-name`, value: seg.name || '', class: 'seg-name', 'aria-label': `segment ${i + 1} name` }));
  nameInput.addEventListener('input', () => {
    const v = nameInput.value.trim();
    const dup = v && segments.some((s, j) => j !== i && s.name === v);
    const err = !v ? 'needs a name' : dup ? 'another segment has this name' : null;
    if (!err) seg.name = v;
    form.setError(nameInput, err);
    form.modified();
  });
  const typeSelect = h('select', { id: `seg-${i}-type`, 'aria-label': `segment ${i + 1} type` },
    ...Object.keys(SEGMENT_TYPES).map((t) => h('option', { value: t, selected: t === type }, t)),
    SEGMENT_TYPES[type] ? null : h('option', { value: type, selected: true }, type));
  typeSelect.addEventListener('change', () => {
    const keep = { type: typeSelect.value, name: seg.name };
    segments[i] = { ...keep, ...structuredClone(NEW_SEGMENT[typeSelect.value] || {}) };
    form.dropErrors(`seg-${i}-`);
    redraw();
    form.modified();
  });
  const params = segmentParams(seg, i, fields, form);
  const count = type === 'positions' || type === 'tilts' ? ` (${(seg.positions_deg || []).length} positions)` : '';
  // The segments' errors are dropped with every change of their order: their ids name the index.
  const reordered = () => {
    form.dropErrors('seg-');
    redraw();
    form.modified();
  };
  const move = (d) => {
    const j = i + d;
    if (j < 0 || j >= segments.length) return;
    [segments[i], segments[j]] = [segments[j], segments[i]];
    reordered();
  };
  return h('tr', { id: `segment-${i}`, dataset: { index: i, name: seg.name || '' }, class: 'segment' },
    h('td', { class: 'num' }, i + 1),
    h('td', {}, nameInput, h('div', { class: 'field-error', id: `seg-${i}-name-error` })),
    h('td', {}, typeSelect),
    h('td', {}, params, count ? h('span', { class: 'muted' }, count) : null,
      h('div', { class: 'field-error', id: `seg-${i}-params-error` }),
      ...fields.map((f) => h('div', { class: 'field-error', id: `seg-${i}-${f.key}-error` })),
      h('ul', { class: 'segment-problems', id: `seg-${i}-problems` })),
    h('td', { class: 'num seg-time', id: `seg-${i}-time` }, ''),
    h('td', { class: 'row-actions' },
      h('button', { type: 'button', class: 'icon', title: 'move up', 'aria-label': `move segment ${i + 1} up`, onclick: () => move(-1) }, '↑'),
      h('button', { type: 'button', class: 'icon', title: 'move down', 'aria-label': `move segment ${i + 1} down`, onclick: () => move(1) }, '↓'),
      h('button', { type: 'button', class: 'icon copy', title: 'duplicate', 'aria-label': `duplicate segment ${i + 1}`, onclick: () => {
        const copy = structuredClone(seg);
        copy.name = uniqueName(segments, `${seg.name || type}-copy`);
        segments.splice(i + 1, 0, copy);
        reordered();
      } }, 'copy'),
      h('button', { type: 'button', class: 'icon danger-text', title: 'delete', 'aria-label': `delete segment ${i + 1}`, onclick: () => {
        segments.splice(i, 1);
        reordered();
      } }, '✕')));
}

// The segment's parameters, one control per field of its type, and the keys the form does not
// know, kept as they are.
function segmentParams(seg, i, fields, form) {
  const params = h('div', { class: 'params' });
  for (const f of fields) {
    const id = `seg-${i}-${f.key}`;
    let control;
    if (f.kind === 'axis') {
      control = h('select', { id, 'aria-label': `segment ${i + 1} ${f.label}` },
        ...AXIS_NAMES.map((a) => h('option', { value: a, selected: seg[f.key] === a }, a)));
      if (!seg[f.key]) seg[f.key] = 'outer';
      control.addEventListener('change', () => { seg[f.key] = control.value; form.modified(); });
    } else {
      const text = formatValue(f, seg[f.key]);
      // A list of positions: one per line in a box that shows them all (twelve positions in
      // one line of text were cut off).
      control = f.kind === 'vec3list'
        ? h('textarea', { id, 'aria-label': `segment ${i + 1} ${f.label}`, class: 'positions', spellcheck: 'false',
          rows: String(Math.min(12, Math.max(2, (seg[f.key] || []).length))), value: text })
        : titled(h('input', { type: 'text', id, value: text, 'aria-label': `segment ${i + 1} ${f.label}`,
          class: f.kind === 'number' ? 'short' : '', spellcheck: 'false' }));
      control.addEventListener('input', () => {
        const r = parseField(f, control.value);
        let err = r.error || null;
        if (r.empty && f.required) err = 'required';
        if (!err) {
          if (r.empty) delete seg[f.key]; else seg[f.key] = r.value;
        }
        if (seg.type === 'rate' && !err) {
          const either = seg.revolutions !== undefined || seg.duration_s !== undefined;
          form.setError(params, either ? null : 'give revolutions or a duration', `seg-${i}-params-error`);
        }
        form.setError(control, err);
        form.modified();
      });
    }
    params.append(h('label', { class: 'param' }, h('span', {}, f.label), control));
  }
  const known = new Set(['type', 'name', ...fields.map((f) => f.key)]);
  const others = Object.keys(seg).filter((k) => !known.has(k));
  if (others.length) params.append(h('span', { class: 'muted', title: 'kept as they are' }, others.map((k) => `${k}: ${JSON.stringify(seg[k])}`).join(', ')));
  return params;
}
