import { h, num } from '../../format.mjs';
import { contributionRows } from '../../contributions.mjs';

// Each stage's contribution, in the body frame: the first stage's value, what each later stage
// changed, the final value and σ, and the filter's sqrt(P0/Pk) for stage 3's states.
export function contributionsTable(stages, reduction) {
  const rows = contributionRows(stages, reduction);
  const body = h('tbody');
  let group = null;
  for (const r of rows) {
    if (r.group !== group) {
      group = r.group;
      body.append(h('tr', { class: 'group-row' }, h('th', { colspan: stages.length + 4 }, group)));
    }
    body.append(h('tr', { dataset: { coefficient: r.name } },
      h('td', { class: 'coef' }, r.name.split('.').slice(1).join('.')),
      h('td', { class: 'unit' }, r.unit),
      ...r.changes.map((c, k) => h('td', { class: 'num' }, c === null ? '—' : (k > 0 && c > 0 ? '+' : '') + num(c, 4))),
      h('td', { class: 'num final' }, num(r.final, 5)),
      h('td', { class: 'num sigma' }, r.sigma === null ? '—' : num(r.sigma, 2)),
      h('td', { class: 'num reduction', title: 'sqrt(P0/Pk): how much stage 3 shrank this state\'s uncertainty' }, r.reduction === null ? '—' : num(r.reduction, 3))));
  }
  return h('div', { class: 'contributions', id: 'contributions' },
    h('h3', {}, 'What each stage contributed (body frame)'),
    h('p', { class: 'muted' }, `The value after ${stages[0].stage}, the change each later stage made, the final value and its σ; ` +
      'sqrt(P0/Pk): the factor by which stage 3 reduced the state\'s uncertainty (large: the program observes it well).'),
    h('table', { class: 'list compact contribution-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'coefficient'), h('th', {}, 'unit'),
        ...stages.map((s, k) => h('th', { class: 'num' }, k === 0 ? s.stage : `Δ ${s.stage}`)),
        h('th', { class: 'num' }, 'final'), h('th', { class: 'num' }, 'σ'), h('th', { class: 'num' }, '√(P0/Pk)'))),
      body));
}
