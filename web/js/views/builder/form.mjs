// The builder's form pieces: an input bound to a path of the campaign JSON, a labelled field with
// its hint and error box, and the field errors the page finds (kept in state.fieldErrors, listed
// in the side panel by the name the form gives each field).
import { h } from '../../format.mjs';

// A text field narrower than what it may hold ("lever-arm/static-x-up", "0, 54.735610317245346, 45")
// keeps its whole value in its tooltip.
export function titled(input) {
  input.title = input.value;
  input.addEventListener('input', () => { input.title = input.value; });
  return input;
}

export function input(id, path, value, attrs = {}) {
  const el = h('input', { id, dataset: { path }, value: value ?? '', ...attrs });
  return el;
}

export function fieldRow(label, control, path, hint) {
  return h('div', { class: 'field', dataset: { field: path } },
    h('label', { for: control.id }, label), control,
    hint ? h('span', { class: 'hint' }, hint) : null,
    h('div', { class: 'field-error', id: `${control.id}-error`, role: 'alert' }));
}

/** setError(el, message, id) shows a field's problem (null: none) in its box under root and keeps
 *  it in state.fieldErrors; dropErrors(prefix) forgets those of fields drawn again. */
export function fieldErrors(root, state) {
  function setError(el, message, id = `${el.id}-error`) {
    const box = root.querySelector(`#${CSS.escape(id)}`);
    if (box) box.textContent = message || '';
    if (el.setAttribute) el.setAttribute('aria-invalid', message ? 'true' : 'false');
    // The side panel lists these away from their fields: each names its field as the form does.
    const name = fieldName(el, id);
    if (message) state.fieldErrors.set(id, name ? `${name}: ${message}` : message); else state.fieldErrors.delete(id);
  }

  // The name the form gives a field: its label, or "segment 3 rate (deg/s)" in the program table.
  function fieldName(el, id) {
    const aria = el.getAttribute?.('aria-label');
    if (aria) return aria;
    const label = el.id && root.querySelector(`label[for="${CSS.escape(el.id)}"]`);
    if (label) return label.textContent.trim();
    const segment = /^seg-(\d+)-/.exec(id);
    return segment ? `segment ${Number(segment[1]) + 1}` : null;
  }

  function dropErrors(prefix) {
    state.fieldErrors = new Map([...state.fieldErrors].filter(([k]) => !k.startsWith(prefix)));
  }
  return { setError, dropErrors };
}
