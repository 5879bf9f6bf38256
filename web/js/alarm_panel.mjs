// The alarms as a table, with an Acknowledge button per alarm not yet acknowledged: shared by the
// list under the header (every page) and the campaign page. A viewer sees the button disabled with
// the reason, as the command buttons (dialogs.mjs).
import { post } from './api.mjs';
import { isOperator } from './session.mjs';
import { h, dateTime } from './format.mjs';
import { alarmStatus, alarmStatusText } from './alarms.mjs';

/** POST /api/alarms/{id}/ack; resolves with the alarm as the daemon now has it. */
export function acknowledgeAlarm(alarm) {
  return post(`/api/alarms/${alarm.id}/ack`, {});
}

/**
 * A table of `alarms`. `campaignColumn`: show which campaign raised each (the list on every page).
 * `onAcknowledged(alarm)` gets the reply; `onError(alarm, error)` the refusal (e.g. 409, already
 * acknowledged by someone else).
 */
export function alarmTable(alarms, { id, campaignColumn = true, onAcknowledged, onError } = {}) {
  const operator = isOperator();
  const rows = alarms.map((a) => {
    const status = alarmStatus(a);
    let action = null;
    if (!a.acknowledged) {
      const button = h('button', { type: 'button', class: 'ack', disabled: !operator,
        title: operator ? 'Record that you have seen this alarm (your name and the time are kept)' : 'operator role required (you are signed in as a viewer)' },
      'Acknowledge');
      button.addEventListener('click', async () => {
        button.disabled = true;
        try {
          onAcknowledged?.(await acknowledgeAlarm(a));
        } catch (e) {
          button.disabled = false;
          onError?.(a, e);
        }
      });
      action = button;
    }
    return h('tr', { class: `alarm alarm-${status} severity-${a.severity}`, dataset: { alarmId: a.id, status, source: a.source, severity: a.severity } },
      h('td', {}, h('span', { class: `badge severity severity-${a.severity}` }, a.severity)),
      campaignColumn ? h('td', {}, h('a', { href: `#/campaigns/${a.campaign}` }, `#${a.campaign} ${a.campaign_name || ''}`)) : null,
      h('td', { class: 'alarm-source' }, a.source),
      h('td', { class: 'alarm-message' }, a.message),
      h('td', { class: 'alarm-raised' }, dateTime(a.raised)),
      h('td', { class: 'alarm-status', title: a.cleared_reason ? `cleared: ${a.cleared_reason}` : '' }, alarmStatusText(a, dateTime)),
      h('td', { class: 'alarm-action' }, action));
  });
  return h('table', { class: 'list compact alarms', id },
    h('thead', {}, h('tr', {}, h('th', {}, 'severity'), campaignColumn ? h('th', {}, 'campaign') : null, h('th', {}, 'source'),
      h('th', {}, 'message'), h('th', {}, 'raised'), h('th', {}, 'state'), h('th', {}, ''))),
    h('tbody', {}, ...rows));
}
