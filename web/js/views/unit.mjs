// One unit's page (issue 17): its calibrations from the registry (GET /api/imus/{serial}), partial
// runs marked as such, each one's verdict against its part number's limits and its change since
// the previous calibration in sigmas, a chosen coefficient over the calibrations as a trend with
// its sigma, the turn-on to turn-on repeatability, and two calibrations side by side
// (GET /api/compare). Each part is a component of views/unit/; this module reads the unit and
// hands each its part.
import { get } from '../api.mjs';
import { h } from '../format.mjs';
import { calibrationsCard } from './unit/calibrations_card.mjs';
import { trendCard } from './unit/trend_card.mjs';
import { compareCard } from './unit/compare_card.mjs';
import { repeatabilityCard } from './unit/repeatability_card.mjs';
import { gravityCorrectedNote } from './unit/gravity_corrected_note.mjs';

export function mount(root, ctx) {
  const serial = ctx.params.serial;
  const url = `/api/imus/${encodeURIComponent(serial)}`;
  const status = h('div', { class: 'form-error', role: 'alert', id: 'unit-error' });
  const info = h('p', { class: 'muted', id: 'unit-info' });
  const gravityNote = gravityCorrectedNote(status);
  const calibrations = calibrationsCard();
  const trend = trendCard();
  const comparison = compareCard();
  const repeatability = repeatabilityCard();

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, `Unit ${serial}`),
      h('div', { class: 'actions' },
        h('a', { class: 'button', id: 'unit-csv', href: `${url}/history.csv`, download: `imu-${serial}-history.csv` }, 'History (CSV)'))),
    status, info, gravityNote.element,
    calibrations.element, trend.element, comparison.element, repeatability.element);

  (async () => {
    try {
      const u = await get(url);
      const list = u.calibrations || [];
      gravityNote.show(u.gravity_corrected || []);
      info.textContent = `${u.part_number ? `Part number ${u.part_number}${u.limits ? ` (limits from ${u.limits})` : ', no acceptance limits'}. ` : ''}${u.calibrations_counted} calibration${u.calibrations_counted === 1 ? '' : 's'} counted of ${list.length} ended campaign${list.length === 1 ? '' : 's'}.`;
      calibrations.show(list);
      comparison.show(list);
      repeatability.show(u.repeatability);
      trend.show(list);
    } catch (e) {
      status.textContent = `Cannot load unit ${serial}: ${e.message}`;
    }
  })();

  return () => trend.destroy();
}
