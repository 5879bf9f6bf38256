// The audit trail (issue 35, docs/api.md "GET /api/audit"): who changed what and when, newest
// first, filtered by actor, action, subject and dates; whether the chain of hashes holds; the same
// rows as CSV for a spreadsheet.
import { get } from '../api.mjs';
import { h, clear, dateTime } from '../format.mjs';

// The details of an entry in one line a person reads: "key: value; ..." (objects as JSON).
function detailsText(details) {
  if (!details || typeof details !== 'object') return details === null || details === undefined ? '' : String(details);
  return Object.entries(details)
    .filter(([, v]) => v !== null && v !== '' && !(Array.isArray(v) && !v.length))
    .map(([k, v]) => `${k.replace(/_/g, ' ')}: ${typeof v === 'object' ? JSON.stringify(v) : v}`)
    .join('; ');
}

export function mount(root) {
  const field = (id, label, attrs = {}) => {
    const input = h('input', { id, name: id, ...attrs });
    return [h('label', { for: id }, label), input];
  };
  const [actorLabel, actor] = field('audit-actor', 'Who', { placeholder: 'a user, or imucald' });
  const [actionLabel, action] = field('audit-action', 'Action', { placeholder: 'e.g. limits. or campaign.' });
  const [subjectLabel, subject] = field('audit-subject', 'About', { placeholder: 'e.g. campaign 7' });
  const [fromLabel, from] = field('audit-from', 'From', { type: 'date' });
  const [toLabel, to] = field('audit-to', 'To', { type: 'date' });
  const show = h('button', { type: 'submit', id: 'audit-show' }, 'Show');
  const csv = h('a', { id: 'audit-csv', class: 'button', download: 'imucal-audit.csv' }, 'CSV');
  const integrity = h('p', { id: 'audit-integrity', role: 'status' });
  const error = h('div', { class: 'form-error', role: 'alert', id: 'audit-error' });
  const body = h('tbody', { id: 'audit-rows' });
  const form = h('form', { class: 'filters', id: 'audit-filters' },
    actorLabel, actor, actionLabel, action, subjectLabel, subject, fromLabel, from, toLabel, to, show, csv);

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, 'Audit trail')),
    h('p', { class: 'hint' }, 'Every change a person or the service made, newest first. Each entry carries the hash of the one ',
      'before it, so an entry edited or deleted afterwards breaks the chain (checked below, and offline with ',
      h('code', {}, 'imucal audit verify DATA_DIR'), ').'),
    integrity, error,
    h('section', { class: 'card' }, form,
      h('table', { class: 'list', id: 'audit-table' },
        h('thead', {}, h('tr', {}, h('th', { class: 'num' }, '#'), h('th', {}, 'When'), h('th', {}, 'Who'),
          h('th', {}, 'Action'), h('th', {}, 'About'), h('th', {}, 'Details'))),
        body)));

  function query(format) {
    const q = new URLSearchParams();
    for (const [key, input] of [['actor', actor], ['action', action], ['subject', subject], ['from', from], ['to', to]])
      if (input.value.trim()) q.set(key, input.value.trim());
    q.set('limit', '500');
    if (format) q.set('format', format);
    return `/api/audit?${q}`;
  }

  async function load() {
    error.textContent = '';
    csv.href = query('csv');
    try {
      const r = await get(query());
      integrity.textContent = r.intact ? `Chain intact: ${r.check}.` : `CHAIN BROKEN: ${r.check}`;
      integrity.className = r.intact ? 'result-ok' : 'result-bad';
      clear(body).append(...r.entries.map((e) => h('tr', { dataset: { seq: e.seq, action: e.action } },
        h('td', { class: 'num' }, e.seq), h('td', { class: 'when' }, dateTime(e.t)), h('td', {}, e.actor), h('td', {}, e.action),
        h('td', { class: 'subject' }, e.subject), h('td', { class: 'details' }, detailsText(e.details)))));
      if (!r.entries.length) body.append(h('tr', {}, h('td', { colspan: 6, class: 'muted' }, 'No entry matches.')));
    } catch (e) {
      error.textContent = `Cannot read the audit trail: ${e.message}`;
    }
  }

  form.addEventListener('submit', (ev) => {
    ev.preventDefault();
    load();
  });
  load();
}
