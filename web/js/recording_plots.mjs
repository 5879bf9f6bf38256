// The recording of a run as plots (GET /api/campaigns/{id}/series): table angles, IMU rates and
// temperatures over program time, each column the minimum and maximum of its frames, so that a
// 12 h run opens at once and no excursion is lost. Drag across a plot to zoom: the range is read
// again from the recording at full detail; "Whole run" goes back.
import { get } from './api.mjs';
import { h, duration } from './format.mjs';
import { lineChart, COLORS } from './plots.mjs';

const POINTS = 800;

// The chart specs: which channels of the series reply, under which title and unit.
const CHARTS = [
  { key: 'table_deg', title: 'Table angles', unit: '°', channels: ['outer', 'middle', 'inner'] },
  { key: 'gyro_dps', title: 'IMU angular rate (gyro increments over the frame interval)', unit: '°/s', channels: ['x', 'y', 'z'] },
  { key: 'temperature_C', title: 'Temperatures: chamber, its set point, the sensors', unit: '°C',
    channels: ['chamber', 'setpoint', 'gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z'] },
];

/**
 * uPlot data from a series reply for one chart: x (program seconds) and, per channel present,
 * its maximum and minimum per column. Pure, for the unit tests.
 * @returns {{labels: string[], data: (number|null)[][]}}
 */
export function chartData(series, key, channels) {
  const group = series[key] || {};
  const present = channels.filter((c) => group[c]);
  const labels = [];
  const data = [series.t_s.slice()];
  for (const c of present) {
    labels.push(`${c} max`, `${c} min`);
    data.push(group[c].max, group[c].min);
  }
  return { labels, data };
}

/**
 * Mounts the plots in `box`; returns a function that removes them, with `.reload()` to read the
 * recording again (a running campaign's grows) unless the operator has zoomed in.
 */
export function recordingPlots(box, campaignId) {
  const status = h('p', { class: 'muted', id: 'recording-plots-status' }, 'Reading the recording…');
  const whole = h('button', { type: 'button', class: 'small', id: 'recording-whole', hidden: true }, 'Whole run');
  box.append(h('div', { class: 'recording-toolbar' }, status, whole));
  const charts = [];
  let stopped = false;
  let zoomed = false;

  async function load(from_s, to_s) {
    zoomed = from_s !== undefined;
    const q = new URLSearchParams({ points: String(POINTS) });
    if (from_s !== undefined) { q.set('from_s', String(Math.max(0, from_s))); q.set('to_s', String(to_s)); }
    let series;
    try {
      series = await get(`/api/campaigns/${campaignId}/series?${q}`);
    } catch (e) {
      status.textContent = `Cannot read the recording: ${e.message}`;
      status.className = 'form-error';
      return;
    }
    if (stopped) return;
    const frames = series.frames.reduce((a, b) => a + b, 0);
    status.textContent = `${zoomed ? 'Zoomed' : 'Whole run'}: ${duration(series.from_s)} – ${duration(series.to_s)}, ` +
      `${frames} frames in ${series.t_s.length} columns (each the minimum and maximum of its frames). Drag across a plot to zoom in.`;
    status.dataset.frames = String(frames);
    whole.hidden = !zoomed;
    for (const c of charts) c.destroy();
    charts.length = 0;
    for (const spec of CHARTS) {
      let el = box.querySelector(`#recording-${spec.key}`);
      if (!el) box.append(el = h('div', { class: 'recording-plot', id: `recording-${spec.key}` }));
      el.replaceChildren();
      const { labels, data } = chartData(series, spec.key, spec.channels);
      if (!labels.length) continue;
      const chart = lineChart(el, {
        title: `${spec.title} [${spec.unit}]`, x: 'program time (s)', y: spec.unit, height: 190, points: false,
        // Temperatures come a few a minute: a zoomed column may hold none, so their lines join
        // across empty columns (frames never leave a column empty while the IMU records).
        series: labels.map((label, i) => ({ label, color: COLORS[Math.floor(i / 2) % COLORS.length], width: i % 2 ? 0.8 : 1.2,
          spanGaps: spec.key === 'temperature_C' })),
        onZoom: (x0, x1) => load(x0, x1),
      });
      chart.setData(data);
      charts.push(chart);
    }
  }
  whole.addEventListener('click', () => load());
  load();
  return Object.assign(() => {
    stopped = true;
    for (const c of charts) c.destroy();
  }, { reload: () => (zoomed || stopped ? undefined : load()) });
}
