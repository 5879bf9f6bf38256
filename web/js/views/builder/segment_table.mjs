// The builder's program segments: a row per segment (segment_row.mjs) and the control that adds
// one of a chosen type.
import { h, clear } from '../../format.mjs';
import { SEGMENT_TYPES, NEW_SEGMENT } from '../../program_edit.mjs';
import { segmentRow, uniqueName } from './segment_row.mjs';

/** The card; render() draws the rows from state.draft. form: setError, dropErrors, modified()
 *  after an edit. */
export function segmentTable(state, form) {
  const segmentsBody = h('tbody', { id: 'segments' });
  const addType = h('select', { id: 'add-type' }, ...Object.keys(SEGMENT_TYPES).map((t) => h('option', { value: t }, t)));
  const element = h('section', { class: 'card' },
    h('div', { class: 'section-head' }, h('h2', {}, 'Program segments'),
      h('div', { class: 'actions' }, h('label', { for: 'add-type' }, 'Add'), addType,
        h('button', { type: 'button', id: 'add-segment', onclick: () => addSegment(addType.value) }, 'Add segment'))),
    h('table', { class: 'segments' },
      h('thead', {}, h('tr', {}, h('th', {}, '#'), h('th', {}, 'Name'), h('th', {}, 'Type'), h('th', {}, 'Parameters'),
        h('th', { class: 'num' }, 'Time'), h('th', {}, ''))),
      segmentsBody));

  function render() {
    clear(segmentsBody);
    state.draft.program.segments.forEach((seg, i) => segmentsBody.append(segmentRow(state, seg, i, { form, redraw: render })));
  }

  function addSegment(type) {
    const segments = state.draft.program.segments;
    segments.push({ type, name: uniqueName(segments, type), ...structuredClone(NEW_SEGMENT[type]) });
    render();
    form.modified();
    segmentsBody.lastElementChild?.querySelector('input')?.focus();
  }
  return { element, render };
}
