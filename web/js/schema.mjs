// The model's coefficients as imucald names them (GET /api/schema, docs/api.md): every key in
// order with its group, title and unit, the groups' titles, stage 3's states and the seed's
// targets. The C++ owns these tables (core/coefficients.cpp, plan/); the page asks for them once,
// after sign-in and before any page shows (main.mjs), and every module reads them here, so that
// a coefficient imucald gains or renames shows everywhere without an edit of web/
// (tests/architecture/check_web_coefficient_names.py refuses a copy).

let current = null;
let loading = null;

/** Indexes the document as GET /api/schema answers it; the unit tests give it a file's copy. */
export function setSchema(doc) {
  const coefficients = Array.isArray(doc?.coefficients) ? doc.coefficients : [];
  current = Object.freeze({
    groups: Array.isArray(doc?.groups) ? doc.groups : [],
    coefficients,
    byKey: new Map(coefficients.map((c) => [c.key, c])),
    seedTargets: Object.freeze(Object.fromEntries((doc?.seed_targets || []).map((t) => [t.group, t.sigma]))),
  });
  return current;
}

/** The schema; an error when it is not loaded yet (a page shown before main.mjs asked for it). */
export function schema() {
  if (!current) throw new Error('the coefficients (GET /api/schema) are not loaded yet');
  return current;
}

export function schemaLoaded() {
  return current !== null;
}

/** Asks imucald once (`get`: api.mjs's); later calls share the answer, a failed one is asked again. */
export function loadSchema(get) {
  if (current) return Promise.resolve(current);
  if (!loading) loading = get('/api/schema').then(setSchema).finally(() => { loading = null; });
  return loading;
}
