// The uncertainty budget (issue 34; the model's `budget` section, docs/calibration.md "Stage 1's
// uncertainty budget"): each source's standard uncertainty per coefficient, as the certificate
// and the builder show it. Pure: the model (or the plan's answer) comes in, rows go out.
import { flatten, orderOf } from './coefficients.mjs';

const NAMES = {
  type_a: 'Measurement (type A)',
  'table.outer_tilt_arcsec': 'Table: outer axis tilt',
  'table.middle_axis_arcsec': 'Table: middle axis',
  'table.inner_axis_arcsec': 'Table: inner axis',
  'table.encoder_error_arcsec.outer': 'Table: outer encoder',
  'table.encoder_error_arcsec.middle': 'Table: middle encoder',
  'table.encoder_error_arcsec.inner': 'Table: inner encoder',
  'site.gravity_mps2': 'Site gravity',
};

/** A budget source in words: "Table: outer axis tilt"; a start model's term "Start model: accel.k2_ug_per_g2". */
export function sourceName(source) {
  if (NAMES[source]) return NAMES[source];
  if (source.startsWith('start_model.')) return `Start model: ${source.slice('start_model.'.length)}`;
  return source;
}

/** Type A first, then the table's, the site's and the start model's sources, each by name. */
function sourceOrder(a, b) {
  const rank = (s) => (s === 'type_a' ? 0 : s.startsWith('table.') ? 1 : s.startsWith('site.') ? 2 : 3);
  return rank(a) - rank(b) || a.localeCompare(b);
}

/**
 * The model's budget as a table: {sources: [source, ...], rows: [{key, contributions: {source:
 * number}, u, dominant}]}, one row per coefficient some source states (a contribution above zero),
 * u the model's sigma (the combined standard uncertainty), dominant the largest contribution's
 * source. Empty rows for a model without a budget.
 */
export function budgetTable(model) {
  const bySource = Object.entries(model?.budget || {}).map(([source, set]) => [source, flatten(set)]);
  const sigma = flatten(model?.sigma);
  const keys = new Set();
  for (const [, values] of bySource) for (const [key, v] of values) if (v > 0) keys.add(key);
  const sources = bySource.filter(([, values]) => [...values.values()].some((v) => v > 0)).map(([s]) => s).sort(sourceOrder);
  const rows = [...keys].sort((a, b) => orderOf(a) - orderOf(b) || a.localeCompare(b)).map((key) => {
    const contributions = {};
    for (const [source, values] of bySource) if (values.get(key) > 0) contributions[source] = values.get(key);
    const dominant = Object.entries(contributions).reduce((d, e) => (d === null || e[1] > d[1] ? e : d), null)[0];
    return { key, contributions, u: sigma.get(key) ?? null, dominant };
  });
  return { sources, rows };
}
