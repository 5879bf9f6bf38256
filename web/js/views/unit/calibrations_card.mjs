// A unit's calibrations (issue 17): each ended campaign that named it, with the stand that ran
// it (issue 38: a lab's registry gathers every stand's), partial runs marked as such, whether it
// counts as a calibration, its verdict against its part number's limits and its change since the
// previous calibration in sigmas.
import { h, clear, dateTime, outcomeBadge, num } from '../../format.mjs';
import { verdictBadge } from '../../components/verdict_badge.mjs';

/** The card; show(calibrations) fills its table. */
export function calibrationsCard() {
  const body = h('tbody', { id: 'unit-calibrations' });
  const element = h('section', { class: 'card' }, h('h2', {}, 'Calibrations'),
    h('table', { class: 'list', id: 'unit-table' },
      h('thead', {}, h('tr', {}, h('th', { class: 'num' }, '#'), h('th', {}, 'Stand'), h('th', {}, 'Name'), h('th', {}, 'Program'),
        h('th', {}, 'Ended'), h('th', {}, 'State'), h('th', {}, 'Counts as a calibration'), h('th', {}, 'Verdict'),
        h('th', {}, 'Change since the previous'), h('th', {}, 'Recording'))),
      body));
  const show = (calibrations) => clear(body).append(...calibrations.map((c) => h('tr', { dataset: { id: c.campaign_id, complete: String(c.complete) } },
    h('td', { class: 'num' }, campaignLink(c)),
    h('td', {}, c.stand || ''), h('td', {}, c.name), h('td', {}, c.program), h('td', {}, dateTime(c.date)),
    h('td', {}, outcomeBadge(c)),
    h('td', {}, counts(c)), h('td', {}, verdictCell(c.verdict)), h('td', {}, changeCell(c.change)),
    h('td', {}, recordingLink(c)))));
  return { element, show };
}

// Another stand's campaign opens on that stand's own page (its id is that stand's), when the
// registry knows its address.
function campaignLink(c) {
  const page = c.links ? c.links.campaign_page : `#/campaigns/${c.campaign_id}`;
  return page ? h('a', { href: page, title: c.stand ? `on ${c.stand}` : '' }, c.campaign_id) : String(c.campaign_id);
}

// The recording from this stand, the lab's archive or the stand that holds it (GET /api/imus/{serial} links).
function recordingLink(c) {
  const l = c.links;
  if (!l) return '';
  if (!l.recording) return h('span', { class: 'small', title: l.note || '' }, 'not reachable');
  return h('a', { href: l.recording, download: '', class: 'recording-link' }, `download (${l.recording_from})`);
}

function counts(c) {
  if (c.counts && c.complete) return 'yes';
  if (c.counts) return `yes, partial run accepted: ${c.accepted?.reason || ''}`;
  if (!c.model) return 'no: no model';
  return `no: partial (${Math.round(100 * (c.progress || 0))} % of the program), not accepted`;
}

function verdictCell(v) {
  if (!v) return verdictBadge(null);
  const failing = v.coefficients.filter((c) => !c.pass);
  return h('span', {}, verdictBadge(v.pass, failing.map((c) => `${c.key}: ${c.reason}`).join('\n')),
    failing.length ? h('span', { class: 'small' }, ` ${failing.map((c) => `${c.key}: ${c.reason}`).join('; ')}`) : '');
}

function changeCell(ch) {
  if (!ch) return '—';
  const values = Object.values(ch.in_sigmas || {});
  const largest = values.length ? Math.max(...values.map(Math.abs)) : null;
  return h('span', { class: ch.significant.length ? 'result-bad' : '', title: Object.entries(ch.in_sigmas).map(([k, v]) => `${k}: ${num(v, 2)} σ`).join('\n') },
    ch.significant.length ? `${ch.significant.length} significant (${ch.significant.join(', ')})` : 'none significant',
    largest !== null ? `, largest ${num(largest, 2)} σ` : '');
}
