// uPlot wrappers: charts that follow their container's width, bands for +-sigma and tolerance,
// and one drawing pass per animation frame however many messages arrived in between (10 Hz
// telemetry never makes more than one redraw per chart per frame, and none while the tab is
// hidden, since browsers pause animation frames then).
import uPlot from '../vendor/uPlot.esm.js';
import { clockTick, axisTicks, axisUnit } from './format.mjs';

export const COLORS = ['#1565c0', '#c62828', '#2e7d32', '#6a1b9a', '#ef6c00', '#00838f'];
export const AXIS_COLORS = { outer: COLORS[0], middle: COLORS[1], inner: COLORS[2], x: COLORS[0], y: COLORS[1], z: COLORS[2] };

const dirty = new Set();
let frameRequested = false;

/** Calls fn on the next animation frame, once, however often it is asked for before then. */
export function schedule(fn) {
  dirty.add(fn);
  if (!frameRequested) {
    frameRequested = true;
    requestAnimationFrame(() => {
      frameRequested = false;
      const work = [...dirty];
      dirty.clear();
      for (const f of work) {
        try {
          f();
        } catch (e) {
          console.error('plot update failed', e);
        }
      }
    });
  }
}

/**
 * A line chart in `el`.
 * @param {HTMLElement} el
 * @param {{title?: string, y?: string, x?: 'time'|string, height?: number,
 *          series: {label: string, color?: string, dash?: number[], width?: number, band?: boolean}[],
 *          bands?: [number, number, string][], yRange?: (u, min, max) => [number, number],
 *          log?: boolean, points?: boolean, markers?: () => number[], onZoom?: (x0, x1) => void,
 *          xIntegers?: boolean}} spec
 *   markers: x positions drawn as dashed vertical lines (e.g. the restarts of stage 3's navigation).
 *   onZoom: called with the x range a drag selected (charts whose x is not time zoom by dragging).
 *   xIntegers: x counts things (calibrations 1, 2, 3): ticks at whole numbers only.
 * Linear axes label their ticks at one scale (format.mjs axisTicks), the power of ten beside the
 * unit; the labels drawn are kept in the chart's data-x-ticks and data-y-ticks (the canvas cannot
 * be read by a test).
 */
export function lineChart(el, spec) {
  const time = (spec.x ?? 'time') === 'time';
  const height = spec.height ?? 170;
  const series = [{ label: time ? 'time' : spec.x }];
  spec.series.forEach((s, i) => {
    series.push({
      label: s.label,
      stroke: s.band ? 'transparent' : (s.color || COLORS[i % COLORS.length]),
      width: s.band ? 0 : (s.width ?? 1.5),
      dash: s.dash,
      spanGaps: s.spanGaps ?? false,
      // uPlot shows the points by itself when they are sparse (an estimator's first few updates).
      points: spec.points === undefined ? { size: 5 } : { show: spec.points, size: 4 },
      value: s.value || ((u, v) => (v == null ? '—' : formatTick(v))),
      show: true,
    });
  });
  // The power of ten each linear axis is written in, set as its ticks are labelled (uPlot labels
  // the ticks before it draws the axis's title, so the title can say it).
  const exponents = { x: 0, y: 0 };
  const linearTicks = (key) => (u, vals, axisIdx, space, incr) => {
    const t = axisTicks(vals, incr);
    exponents[key] = t.exponent;
    u.root.dataset[`${key}Ticks`] = t.labels.join(' ');
    return t.labels;
  };
  const logTicks = (key) => (u, vals) => {
    const labels = vals.map(formatTick);
    u.root.dataset[`${key}Ticks`] = labels.join(' ');
    return labels;
  };
  const opts = {
    title: spec.title,
    width: Math.max(200, el.clientWidth || 400),
    height,
    series,
    bands: (spec.bands || []).map(([hi, lo, fill]) => ({ series: [hi, lo], fill })),
    scales: {
      x: { time, distr: spec.log ? 3 : 1 },
      y: { distr: spec.log ? 3 : 1, range: spec.yRange },
    },
    axes: [
      { stroke: '#555', grid: { stroke: '#eee' }, ticks: { stroke: '#ddd' },
        label: time ? undefined : spec.log ? spec.x : () => axisUnit(spec.x, exponents.x),
        labelSize: 18, labelGap: 0, size: 30,
        // Whole seconds at least on a time axis: an idle chart's span of a few milliseconds once
        // gave a row of identical "14:03:25" ticks. Whole numbers for counted things.
        ...(time ? { incrs: TIME_INCRS_S } : spec.xIntegers ? { incrs: INTEGER_INCRS } : {}),
        // "14:03:25" needs about 60 px: ticks further apart than uPlot's 50 px, or they run together.
        ...(time ? { space: 80 } : {}),
        values: time ? (u, vals, axis, space, incr) => {
          const labels = vals.map((v) => clockTick(v, incr));
          u.root.dataset.xTicks = labels.join(' ');
          return labels;
        } : spec.log ? logTicks('x') : linearTicks('x') },
      { stroke: '#555', grid: { stroke: '#eee' }, ticks: { stroke: '#ddd' },
        label: spec.log ? spec.y : () => axisUnit(spec.y, exponents.y), labelSize: 22, size: 56,
        // About six ticks whatever the height, never closer than 16 px (a label is 12 px high):
        // a plot 100 px high still gets five or six, so even a range of 480° keeps three labels
        // (0 and 200 alone at uPlot's 30 px), and a tall one is not crowded.
        space: (u, axisIdx, min, max, dim) => Math.max(16, Math.min(30, dim / 6)),
        values: spec.log ? logTicks('y') : linearTicks('y') },
    ],
    legend: { show: spec.legend ?? true, live: true },
    cursor: { drag: { x: !time, y: false } },
    hooks: {
      ...(spec.markers ? { draw: [(u) => drawMarkers(u, spec.markers())] } : {}),
      // A drag selected a range of x (the chart zooms to it): tell whoever can fetch its detail.
      ...(spec.onZoom ? { setSelect: [(u) => {
        if (u.select.width < 2) return;
        spec.onZoom(u.posToVal(u.select.left, 'x'), u.posToVal(u.select.left + u.select.width, 'x'));
      }] } : {}),
    },
  };
  const empty = [[], ...spec.series.map(() => [])];
  const chart = new uPlot(opts, empty, el);
  chart.root.dataset.points = '0';
  let lastWidth = opts.width;
  const resize = new ResizeObserver(() => {
    const w = Math.max(200, el.clientWidth);
    if (Math.abs(w - lastWidth) > 2) {
      lastWidth = w;
      chart.setSize({ width: w, height });
    }
  });
  resize.observe(el);
  return {
    chart,
    setData(data) {
      chart.setData(data);
      // For tests and for anyone curious: how many points are drawn and the newest x.
      chart.root.dataset.points = String(data[0].length);
      chart.root.dataset.lastX = data[0].length ? String(data[0][data[0].length - 1]) : '';
    },
    destroy() {
      resize.disconnect();
      chart.destroy();
    },
  };
}

// Tick spacings of a time axis (seconds) and of a count.
const TIME_INCRS_S = [1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600, 7200, 10800, 21600, 43200, 86400, 172800, 604800];
const INTEGER_INCRS = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000];

function drawMarkers(u, xs) {
  const { ctx, bbox } = u;
  ctx.save();
  ctx.strokeStyle = '#888';
  ctx.setLineDash([4, 4]);
  ctx.lineWidth = 1;
  for (const x of xs || []) {
    if (x < u.scales.x.min || x > u.scales.x.max) continue;
    const px = Math.round(u.valToPos(x, 'x', true)) + 0.5;
    ctx.beginPath();
    ctx.moveTo(px, bbox.top);
    ctx.lineTo(px, bbox.top + bbox.height);
    ctx.stroke();
  }
  ctx.restore();
}

export function formatTick(v) {
  if (v == null || !Number.isFinite(v)) return '';
  const a = Math.abs(v);
  if (a === 0) return '0';
  if (a >= 1e5 || a < 1e-3) return v.toExponential(1);
  if (a >= 100) return v.toFixed(0);
  if (a >= 10) return v.toFixed(1);
  if (a >= 1) return v.toFixed(2);
  return String(Number(v.toPrecision(3)));
}
