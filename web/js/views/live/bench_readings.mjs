// The live page's small cards of bench readings: the table's angles and rates, the chamber's
// temperature against its set point, the IMU's frames and the recorder's queue, each with its
// flags, and the estimators' status (estimator_status.mjs).
import { h, clear, fixed } from '../../format.mjs';
import { AXIS_COLORS } from '../../plots.mjs';
import { AXES } from '../../live.mjs';
import { estimatorStatus } from './estimator_status.mjs';

/** The cards; draw(m, run, store) shows the latest telemetry m (run: its run, or null);
 *  showStatus(s) the table's dialect and the chamber's register map from imucald's status. */
export function benchReadings() {
  const element = h('div', { class: 'cards' });
  const estimators = estimatorStatus();
  const cell = (id) => h('span', { class: 'value', id });
  const kv = (label, id, unit = '') => h('div', { class: 'kv' }, h('span', { class: 'label' }, label), cell(id), unit ? h('span', { class: 'unit' }, unit) : null);
  element.append(
    h('section', { class: 'card small', id: 'table-card' }, h('h2', {}, 'Table'),
      h('table', { class: 'axes' }, h('thead', {}, h('tr', {}, h('th', {}, ''), h('th', { class: 'num' }, 'angle °'), h('th', { class: 'num' }, 'rate °/s'))),
        h('tbody', {}, ...AXES.map((a) => h('tr', {}, h('th', { style: `color:${AXIS_COLORS[a]}` }, a), h('td', { class: 'num', id: `angle-${a}` }), h('td', { class: 'num', id: `rate-${a}` }))))),
      h('div', { class: 'flags', id: 'table-flags' }),
      h('p', { class: 'map-note', id: 'table-dialect', hidden: true })),
    h('section', { class: 'card small', id: 'chamber-card' }, h('h2', {}, 'Chamber'),
      kv('temperature', 'chamber-temp', '°C'), kv('set point', 'chamber-sp', '°C'), kv('tolerance', 'chamber-tol', '± °C'),
      h('div', { class: 'flags', id: 'chamber-flags' }),
      h('p', { class: 'map-note', id: 'chamber-map', hidden: true })),
    h('section', { class: 'card small', id: 'imu-card' }, h('h2', {}, 'IMU and recorder'),
      kv('frame rate', 'imu-rate', 'Hz'), kv('frames', 'imu-frames'), kv('lost', 'imu-lost'), kv('bad', 'imu-bad'),
      kv('recorder queue', 'rec-queue', 'frames'), kv('committed', 'rec-committed', 'frames'),
      h('div', { class: 'flags', id: 'imu-flags' })),
    estimators.element);

  const set = (id, text) => {
    const el = element.querySelector(`#${id}`);
    if (el && el.textContent !== text) el.textContent = text;
  };
  const flags = (id, list) => {
    const el = element.querySelector(`#${id}`);
    const sig = list.map((f) => f.join(':')).join('|');
    if (!el || el.dataset.sig === sig) return;
    el.dataset.sig = sig;
    clear(el).append(...list.map(([cls, text]) => h('span', { class: `flag ${cls}` }, text)));
  };

  function draw(m, run, store) {
    const tb = m.table || {};
    AXES.forEach((a, i) => {
      set(`angle-${a}`, fixed(tb.angle_deg?.[i], 3));
      set(`rate-${a}`, fixed(tb.rate_dps?.[i], 3));
    });
    flags('table-flags', [
      tb.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      tb.homed ? ['ok', 'homed'] : ['warn', 'not homed'],
      tb.interlock_closed ? ['warn', 'interlock closed (may move)'] : ['ok', 'interlock open'],
      ...(tb.fault ? [['bad', `fault: ${tb.fault}`]] : []),
    ]);
    const ch = m.chamber || {};
    set('chamber-temp', fixed(ch.temperature_C, 2));
    set('chamber-sp', fixed(ch.setpoint_C, 2));
    set('chamber-tol', fixed(ch.tolerance_C, 2));
    flags('chamber-flags', [
      ch.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      ch.in_band === false ? ['bad', 'out of band'] : ['ok', 'in band'],
    ]);
    // A run's counters belong to the run: the idle bench shows none of the last run's figures.
    const imu = run ? (m.imu || {}) : { connected: m.imu?.connected };
    set('imu-rate', fixed(imu.frame_rate_hz, 1));
    set('imu-frames', String(imu.frames ?? '—'));
    set('imu-lost', String(imu.lost_frames ?? '—'));
    set('imu-bad', String(imu.bad_frames ?? '—'));
    const rec = run ? (m.recorder || {}) : {};
    set('rec-queue', `${rec.queue_frames ?? '—'} (peak ${rec.queue_high_water_frames ?? '—'})`);
    set('rec-committed', String(rec.committed_frames ?? '—'));
    flags('imu-flags', [
      imu.connected === false ? ['bad', 'disconnected'] : ['ok', 'connected'],
      ...(imu.lost_frames > 0 ? [['warn', `${imu.lost_frames} lost`]] : []),
      ...(imu.bad_frames > 0 ? [['warn', `${imu.bad_frames} bad`]] : []),
      ...(rec.dropped_frames > 0 ? [['bad', `recorder dropped ${rec.dropped_frames}`]] : []),
      ...(store.droppedMessages > 0 ? [['warn', `${store.droppedMessages} live messages skipped (slow page)`]] : []),
    ]);
    estimators.draw(run, run ? (m.estimators || {}) : {});
  }

  // The chamber controller's register map, and whether the maker's manual vouches for it; the
  // table controller's dialect and what it was written from (GET /api/status chamber_map and
  // table_dialect; none on the in-process simulation).
  function showStatus(s) {
    const td = s?.table_dialect;
    const tel = element.querySelector('#table-dialect');
    if (td && tel) {
      tel.textContent = `Dialect ${td.name}`;
      tel.title = td.source;
      tel.hidden = false;
    }
    const cm = s?.chamber_map;
    const el = element.querySelector('#chamber-map');
    if (!cm || !el) return;
    el.textContent = `Register map ${cm.name}: ${cm.summary}.`;
    el.dataset.checked = cm.checked;
    if (cm.checked !== 'yes') el.classList.add('warn-text');
    el.hidden = false;
  }
  return { element, draw, showStatus };
}
