// Formatting and small DOM helpers shared by the views. Every text that comes from the server is
// put into the page with textContent (h() below), never as HTML.
import { runOutcome } from './outcome.mjs';

/** Creates an element: h('td', {class: 'num', title: 'x'}, 'text', childNode, ...). */
export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') el.className = v;
    else if (k === 'dataset') Object.assign(el.dataset, v);
    else if (k.startsWith('on') && typeof v === 'function') el.addEventListener(k.slice(2), v);
    else if (k === 'value') el.value = v;
    else if (k === 'checked' || k === 'disabled' || k === 'selected' || k === 'hidden') el[k] = Boolean(v);
    else el.setAttribute(k, v === true ? '' : String(v));
  }
  append(el, children);
  return el;
}

function append(el, children) {
  for (const c of children) {
    if (c === undefined || c === null || c === false) continue;
    if (Array.isArray(c)) append(el, c);
    else el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
}

export function clear(el) {
  while (el.firstChild) el.removeChild(el.firstChild);
  return el;
}

/** Replaces el's children, skipping null, undefined and false as h() does (Element.append would print "null"). */
export function fill(el, ...children) {
  append(clear(el), children);
  return el;
}

/** Seconds as "1 h 02 min", "6 min 42 s", "12.3 s", "5.1 ms". */
export function duration(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return '—';
  const sign = s < 0 ? '-' : '';
  s = Math.abs(s);
  // Below a tenth of a second (a program at ×100000 takes milliseconds of wall time) in ms, so
  // that a time that is not zero never reads "0.0 s".
  if (s > 0 && s < 0.0995) return s < 1e-4 ? `${sign}under 0.1 ms` : `${sign}${num(s * 1000, 2)} ms`;
  if (s < 9.95) return `${sign}${s.toFixed(1)} s`;
  // Rounded once, at the precision shown, so that 119.6 s is "2 min 00 s", never "1 min 60 s".
  const wholeSeconds = Math.round(s);
  if (wholeSeconds < 60) return `${sign}${wholeSeconds} s`;
  if (wholeSeconds < 3600) return `${sign}${Math.floor(wholeSeconds / 60)} min ${String(wholeSeconds % 60).padStart(2, '0')} s`;
  const wholeMinutes = Math.round(s / 60);
  return `${sign}${Math.floor(wholeMinutes / 60)} h ${String(wholeMinutes % 60).padStart(2, '0')} min`;
}

/** ISO time as local "2025-03-01 21:04:05". */
export function dateTime(iso) {
  if (!iso) return '—';
  const d = new Date(iso);
  if (Number.isNaN(d.getTime())) return String(iso);
  const p = (n) => String(n).padStart(2, '0');
  return `${d.getFullYear()}-${p(d.getMonth() + 1)}-${p(d.getDate())} ${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}`;
}

export function timeOfDay(iso) {
  const s = dateTime(iso);
  return s.length > 11 ? s.slice(11) : s;
}

/** A number with `digits` significant digits, plain or exponential as suits its size. */
export function num(v, digits = 4) {
  if (v === null || v === undefined) return '—';
  if (typeof v !== 'number' || !Number.isFinite(v)) return String(v);
  if (v === 0) return '0';
  const a = Math.abs(v);
  if (a >= 1e-3 && a < 1e6) {
    const decimals = Math.max(0, digits - 1 - Math.floor(Math.log10(a)));
    return v.toFixed(Math.min(decimals, 8));
  }
  return v.toExponential(digits - 1);
}

export function fixed(v, decimals) {
  if (typeof v !== 'number' || !Number.isFinite(v)) return '—';
  const t = v.toFixed(decimals);
  return /^-0(\.0*)?$/.test(t) ? t.slice(1) : t;  // a table at -0.0001° reads 0.000, not -0.000
}

export const FINAL_STATES = new Set(['done', 'failed', 'aborted']);
export const ACTIVE_STATES = new Set(['running', 'pausing', 'paused', 'suspended', 'stopping', 'aborting']);

export function stateBadge(state) {
  return h('span', { class: `badge state-${state || 'unknown'}`, 'data-state': state }, state || '—');
}

/** One badge for what a run amounts to (outcome.mjs): done, stopped, partial, failed, aborted, or its live state. */
export function outcomeBadge(c) {
  const o = runOutcome(c);
  return h('span', { class: `badge state-${o.outcome}`, 'data-state': c.state, 'data-outcome': o.outcome, title: o.title }, o.outcome);
}

/** Which commands the run-state table of docs/api.md allows from a state. */
export function allowedCommands(state) {
  const table = {
    created: ['start', 'abort'],
    queued: ['abort'],
    running: ['pause', 'stop', 'abort'],
    pausing: ['stop', 'abort'],
    paused: ['resume', 'stop', 'abort'],
    suspended: ['stop', 'abort'],
    stopping: ['abort'],
    interrupted: ['resume', 'abort'],
  };
  return table[state] || [];
}

/**
 * A time axis's tick (unix seconds, local time) at the precision of the tick spacing `step_s`:
 * "14:03:25" below a minute, "14:03" below a day, "03-01 14:00" beyond. uPlot's own ticks show a
 * bare ":25" for most spacings, which reads as a number of seconds.
 */
export function clockTick(unix_s, step_s) {
  const d = new Date(unix_s * 1000);
  const two = (n) => String(n).padStart(2, '0');
  const hm = `${two(d.getHours())}:${two(d.getMinutes())}`;
  if (step_s < 60) return `${hm}:${two(d.getSeconds())}`;
  if (step_s < 86400) return hm;
  return `${two(d.getMonth() + 1)}-${two(d.getDate())} ${hm}`;
}

const SUPERSCRIPT = { '-': '⁻', 0: '⁰', 1: '¹', 2: '²', 3: '³', 4: '⁴', 5: '⁵', 6: '⁶', 7: '⁷', 8: '⁸', 9: '⁹' };

/**
 * The labels of a linear axis's ticks `vals`, `incr` apart (uPlot's ticks), all at one scale so
 * that each reads differently: {labels, exponent}. Values far from 1 (below 0.01 or from 10^5)
 * are written in units of 10^exponent, a multiple of 3 (0.000012 °/h as "12" on an axis of
 * "×10⁻⁶ °/h"); the decimals are those of the spacing, so neighbours never share a label (a
 * convergence plot's ticks 1.02e-4 and 1.04e-4 once both read "1.0e-4", or only "0" showed).
 */
export function axisTicks(vals, incr) {
  const finite = vals.filter((v) => Number.isFinite(v));
  const top = Math.max(0, ...finite.map((v) => Math.abs(v)));
  const exponent = top > 0 && (top < 1e-2 || top >= 1e5) ? 3 * Math.floor(Math.log10(top) / 3) : 0;
  const scale = 10 ** exponent;
  const step = Number.isFinite(incr) && incr > 0 ? incr / scale : 1;
  // The spacing's own decimals (0.25 has two), found on the rounded spacing so that 0.1 + 0.2 does not count as 17.
  const stepText = String(Number(step.toPrecision(6)));
  const decimals = /e-(\d+)$/.test(stepText) ? Number(/e-(\d+)$/.exec(stepText)[1]) + (stepText.split('e')[0].split('.')[1]?.length || 0)
    : (stepText.split('.')[1]?.length || 0);
  const labels = vals.map((v) => {
    if (!Number.isFinite(v)) return '';
    const t = (v / scale).toFixed(Math.min(decimals, 12));
    return /^-0(\.0*)?$/.test(t) ? t.slice(1) : t;
  });
  return { labels, exponent };
}

/** An axis's unit with the power of ten its ticks are written in: "×10⁻⁶ °/h". */
export function axisUnit(unit, exponent) {
  if (!exponent) return unit || '';
  const power = `×10${String(exponent).split('').map((c) => SUPERSCRIPT[c]).join('')}`;
  return unit ? `${power} ${unit}` : power;
}
