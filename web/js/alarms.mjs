// Alarms (docs/api.md "Alarms"): how each one reads and what the page keeps of them. Pure (no DOM),
// so that Node tests them (tests/browser/unit.test.mjs); alarm_panel.mjs draws them.
//
// An alarm is active until its condition ends (`cleared` null), and needs an operator until it is
// acknowledged: the list shows every alarm that is active or not acknowledged.

/** 'active' (not acknowledged), 'active-acknowledged', 'cleared' (not acknowledged), 'closed'. */
export function alarmStatus(a) {
  const active = !a.cleared;
  const acknowledged = Boolean(a.acknowledged);
  if (active) return acknowledged ? 'active-acknowledged' : 'active';
  return acknowledged ? 'closed' : 'cleared';
}

/** Whether the alarm still belongs in the list everyone sees. */
export function needsAttention(a) {
  return alarmStatus(a) !== 'closed';
}

/**
 * The list after a change of one alarm (a live message, or an acknowledgement's reply): replaced
 * by id, added when new, dropped once cleared and acknowledged; newest (highest id) first. A copy:
 * the list given is not changed.
 */
export function applyAlarm(list, alarm) {
  const rest = list.filter((a) => a.id !== alarm.id);
  if (needsAttention(alarm)) rest.push(alarm);
  return rest.sort((x, y) => y.id - x.id);
}

/** What the alarm's state column says; `time` formats an ISO time (the page passes dateTime). */
export function alarmStatusText(a, time = (iso) => iso) {
  const parts = [a.cleared ? `cleared ${time(a.cleared)}` : 'active'];
  parts.push(a.acknowledged ? `acknowledged by ${a.acknowledged_by} at ${time(a.acknowledged)}` : 'not acknowledged');
  return parts.join(', ');
}

/** The list's heading: "1 alarm to acknowledge", "3 alarms (2 active), 1 to acknowledge". */
export function alarmSummary(list) {
  const active = list.filter((a) => !a.cleared).length;
  const unacknowledged = list.filter((a) => !a.acknowledged).length;
  const n = list.length;
  const head = `${n} alarm${n === 1 ? '' : 's'}`;
  if (unacknowledged === n && active === 0) return `${head} to acknowledge`;
  const activeText = active ? ` (${active} active)` : '';
  return unacknowledged ? `${head}${activeText}, ${unacknowledged} to acknowledge` : `${head}${activeText}, all acknowledged`;
}
