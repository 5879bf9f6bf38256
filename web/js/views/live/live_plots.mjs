// The live page's plots of the table, the chamber and the IMU over a chosen window (1 min to 1 h
// of the page's own buffers), or over the whole run: the run's recording so far, read from
// imucald (it survives a reload, which the page's own buffers do not), over program time, read
// again every 10 s.
import { h } from '../../format.mjs';
import { lineChart, schedule, AXIS_COLORS, COLORS } from '../../plots.mjs';
import { AXES } from '../../live.mjs';
import { recordingPlots } from '../../recording_plots.mjs';

const WINDOWS = [['60', '1 min'], ['600', '10 min'], ['3600', '1 h'], ['Infinity', 'whole run']];

/** The card; draw() plots the store's window, wholeRunMode() follows the run (on a new one),
 *  destroy() drops the charts. */
export function livePlots(store) {
  let windowS = Number(localStorage.getItem('imucal.live.window') || 600);
  if (!Number.isFinite(windowS) && windowS !== Infinity) windowS = 600;
  // A draw scheduled for the next frame may come after the view was left (its elements gone).
  let destroyed = false;
  const windowSel = h('div', { class: 'tabs small', role: 'tablist', id: 'window-tabs' },
    ...WINDOWS.map(([v, label]) => h('button', { type: 'button', role: 'tab', dataset: { window: v }, 'aria-selected': String(Number(v) === windowS),
      onclick: () => {
        windowS = Number(v);
        localStorage.setItem('imucal.live.window', v);
        for (const b of windowSel.children) b.setAttribute('aria-selected', String(b.dataset.window === v));
        wholeRunMode();
        schedule(draw);
      } }, label)));
  const plotGrid = h('div', { class: 'plot-grid' });
  const plotBox = (id) => h('div', { class: 'plot', id });
  const anglesEl = plotBox('plot-angles'), ratesEl = plotBox('plot-rates'), chamberEl = plotBox('plot-chamber'), rateEl = plotBox('plot-imu-rate');
  plotGrid.append(anglesEl, ratesEl, chamberEl, rateEl);
  const recordingBox = h('div', { class: 'recording-plots', id: 'live-recording', hidden: true });
  const element = h('section', { class: 'card' }, h('div', { class: 'section-head' }, h('h2', {}, 'Table, chamber and IMU'), windowSel), plotGrid, recordingBox);

  let recording = null, recordingRun = null;
  function wholeRunMode() {
    const whole = windowS === Infinity && store.runId !== null;
    plotGrid.hidden = whole;
    recordingBox.hidden = !whole;
    if (whole && recordingRun === store.runId) return;
    recording?.();
    recording = null;
    recordingRun = null;
    recordingBox.replaceChildren();
    if (whole) {
      recording = recordingPlots(recordingBox, store.runId);
      recordingRun = store.runId;
    }
  }
  const recordingTimer = setInterval(() => recording?.reload(), 10000);

  // The charts need their boxes in the page: made by start(), once the card is in it.
  let charts = null;
  function start() {
    const height = 150;  // four plots and the run above them on a 768-pixel screen
    charts = {
      angles: lineChart(anglesEl, { height, title: 'Table angles', y: '°', series: AXES.map((a) => ({ label: a, color: AXIS_COLORS[a] })) }),
      rates: lineChart(ratesEl, { height, title: 'Table rates', y: '°/s', series: AXES.map((a) => ({ label: a, color: AXIS_COLORS[a] })) }),
      chamber: lineChart(chamberEl, { height, title: 'Chamber temperature against set point', y: '°C',
        series: [{ label: 'temperature', color: COLORS[1] }, { label: 'set point', color: '#444', dash: [6, 4] },
          { label: '−tol', band: true }, { label: '+tol', band: true }],
        bands: [[4, 3, 'rgba(46,125,50,0.12)']] }),
      frameRate: lineChart(rateEl, { height, title: 'IMU frame rate', y: 'Hz', series: [{ label: 'frames/s', color: COLORS[3] }] }),
    };
  }

  function draw() {
    if (destroyed) return;
    charts.angles.setData(store.angles.view(windowS));
    charts.rates.setData(store.rates.view(windowS));
    charts.chamber.setData(store.chamber.view(windowS));
    charts.frameRate.setData(store.frameRate.view(windowS));
  }

  function destroy() {
    destroyed = true;
    clearInterval(recordingTimer);
    recording?.();
    for (const c of Object.values(charts || {})) c.destroy();
  }
  return { element, start, draw, wholeRunMode, destroy };
}
