// Every IMU a campaign named (GET /api/imus) with its calibrations and the verdict of its last one.
import { get } from '../../api.mjs';
import { h, clear, dateTime } from '../../format.mjs';
import { verdictBadge } from '../../components/verdict_badge.mjs';

/** The card; load() reads the units afresh (after the limits changed, their verdicts too); a
 *  failure goes to status (the page's error line). */
export function unitsCard(status) {
  const body = h('tbody', { id: 'units-rows' });
  const element = h('section', { class: 'card' }, h('h2', {}, 'Units calibrated here'),
    h('table', { class: 'list', id: 'units-table' },
      h('thead', {}, h('tr', {}, h('th', {}, 'Serial'), h('th', {}, 'Part number'), h('th', { class: 'num' }, 'Campaigns'),
        h('th', { class: 'num' }, 'Calibrations'), h('th', {}, 'Last calibration'), h('th', {}, 'Verdict'))),
      body));
  async function load() {
    try {
      const r = await get('/api/imus');
      clear(body).append(...(r.imus || []).map((u) => h('tr', { dataset: { serial: u.serial } },
        h('td', {}, h('a', { href: `#/imus/${encodeURIComponent(u.serial)}` }, u.serial)),
        h('td', {}, u.part_number || ''), h('td', { class: 'num' }, u.campaigns), h('td', { class: 'num' }, u.calibrations),
        h('td', {}, u.last_calibration ? h('a', { href: `#/campaigns/${u.last_calibration.campaign_id}` },
          `#${u.last_calibration.campaign_id} ${u.last_calibration.program}, ${dateTime(u.last_calibration.date)}`) : '—'),
        h('td', {}, u.last_calibration ? verdictBadge(u.pass) : '—'))));
      if (!(r.imus || []).length) body.append(h('tr', {}, h('td', { colspan: 6, class: 'muted' }, 'No campaign has named a unit yet.')));
    } catch (e) {
      status.textContent = `Cannot list the units: ${e.message}`;
    }
  }
  return { element, load };
}
