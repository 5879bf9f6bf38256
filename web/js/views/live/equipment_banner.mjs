// Reference equipment past its due date or due within a week (GET /api/status
// reference_equipment, judged today by imucald): a campaign will not start without an override.
import { h } from '../../format.mjs';
import { equipmentWarnings } from '../../equipment.mjs';

/** The banner; show(status) shows imucald's status's due dates; destroy() stops asking again. */
export function equipmentBanner(ctx) {
  const element = h('div', { class: 'equipment-banner', id: 'equipment-banner', role: 'alert', hidden: true });
  const show = (s) => {
    const warnings = equipmentWarnings(s?.reference_equipment);
    element.replaceChildren(...(warnings ? [
      ...warnings.lines.map((w) => h('p', { class: w.overdue ? 'overdue' : 'due-soon', dataset: { instrument: w.instrument } }, w.text)),
      h('p', { class: 'consequence' }, warnings.sentence)] : []));
    element.classList.toggle('overdue', Boolean(warnings?.overdue));
    element.hidden = !warnings;
  };
  // A live page left open over days (an unattended night, a weekend) asks again every hour: the
  // due dates are today's.
  const timer = setInterval(() => ctx.status(true).then(show).catch(() => {}), 3600 * 1000);
  return { element, show, destroy: () => clearInterval(timer) };
}
