// Time series for the live plots with bounded memory and bounded drawing cost, however long the
// run: a 12 h campaign at 10 Hz is 432 000 samples per series, far more than a plot can draw 10
// times a second. Each series keeps
//  - a ring buffer of the most recent samples at full rate (the "last minutes" views), and
//  - a history of the whole run decimated by a stride that doubles whenever it fills up, so it
//    always covers everything with at most `historyCapacity` points (the "whole run" view).
// Both are typed arrays allocated once; pushing a sample is O(1) amortised.

export class Series {
  /**
   * @param {number} columns  values per sample (besides the time)
   * @param {{recentCapacity?: number, historyCapacity?: number}} [options]
   */
  constructor(columns, { recentCapacity = 3000, historyCapacity = 2000 } = {}) {
    this.columns = columns;
    this.recentCapacity = recentCapacity;
    this.historyCapacity = historyCapacity - (historyCapacity % 2);  // compaction halves it
    this.clear();
  }

  clear() {
    const { columns } = this;
    this.rt = new Float64Array(this.recentCapacity);
    this.rv = Array.from({ length: columns }, () => new Float64Array(this.recentCapacity));
    this.rHead = 0;  // where the next sample goes
    this.rLen = 0;
    this.ht = new Float64Array(this.historyCapacity);
    this.hv = Array.from({ length: columns }, () => new Float64Array(this.historyCapacity));
    this.hLen = 0;
    this.stride = 1;
    this.sinceKept = 0;  // samples pushed since the last one the history kept
    this.count = 0;      // samples pushed in all
    this.lastT = -Infinity;
  }

  get length() { return this.count; }
  get lastTime() { return this.lastT; }
  /** The samples held, whatever has been pushed: what bounds memory. */
  get heldPoints() { return this.rLen + this.hLen; }

  /** Latest value of a column (NaN when empty). */
  last(column = 0) {
    if (this.rLen === 0) return NaN;
    const i = (this.rHead - 1 + this.recentCapacity) % this.recentCapacity;
    return this.rv[column][i];
  }

  /**
   * Adds a sample. Times must not decrease (a plot's x axis is sorted); a sample older than the
   * last is dropped and false returned. Missing values are NaN (drawn as gaps).
   */
  push(t, values) {
    if (!(t >= this.lastT)) return false;
    this.lastT = t;
    const i = this.rHead;
    this.rt[i] = t;
    for (let c = 0; c < this.columns; c++) this.rv[c][i] = toNumber(values[c]);
    this.rHead = (i + 1) % this.recentCapacity;
    if (this.rLen < this.recentCapacity) this.rLen++;

    if (this.sinceKept === 0) {
      if (this.hLen === this.historyCapacity) this.compact();
      const j = this.hLen++;
      this.ht[j] = t;
      for (let c = 0; c < this.columns; c++) this.hv[c][j] = toNumber(values[c]);
    }
    this.sinceKept = (this.sinceKept + 1) % this.stride;
    this.count++;
    return true;
  }

  // Keeps every other history sample and doubles the stride: the history still spans the whole
  // run, at half the resolution.
  compact() {
    const n = this.hLen >> 1;
    for (let k = 0; k < n; k++) {
      this.ht[k] = this.ht[2 * k];
      for (let c = 0; c < this.columns; c++) this.hv[c][k] = this.hv[c][2 * k];
    }
    this.hLen = n;
    this.stride *= 2;
    // The sample being added now is the first of the new stride.
    this.sinceKept = 0;
  }

  /** Time span covered by the full-rate ring buffer, seconds. */
  recentSpan() {
    if (this.rLen < 2) return 0;
    const first = (this.rHead - this.rLen + this.recentCapacity) % this.recentCapacity;
    return this.lastT - this.rt[first];
  }

  /**
   * Columns for uPlot, [times, col0, col1, ...], covering the last `spanS` seconds (Infinity:
   * the whole run). Uses the full-rate buffer when it covers the span, else the decimated
   * history plus the newest sample. At most `maxPoints` points (further thinned evenly).
   */
  view(spanS = Infinity, maxPoints = 4000) {
    const fromRecent = this.rLen > 0 && (this.count === this.rLen || spanS <= this.recentSpan());
    let times, cols;
    if (fromRecent) {
      const start = (this.rHead - this.rLen + this.recentCapacity) % this.recentCapacity;
      const t0 = this.lastT - spanS;
      let skip = 0;  // samples older than the window (times are sorted: binary search)
      let lo = 0, hi = this.rLen;
      while (lo < hi) {
        const mid = (lo + hi) >> 1;
        if (this.rt[(start + mid) % this.recentCapacity] < t0) lo = mid + 1; else hi = mid;
      }
      skip = lo;
      const n = this.rLen - skip;
      const step = Math.max(1, Math.ceil(n / maxPoints));
      const m = Math.ceil(n / step);
      times = new Array(m);
      cols = Array.from({ length: this.columns }, () => new Array(m));
      for (let k = 0; k < m; k++) {
        const idx = (start + skip + k * step) % this.recentCapacity;
        times[k] = this.rt[idx];
        for (let c = 0; c < this.columns; c++) cols[c][k] = gap(this.rv[c][idx]);
      }
      // Always end on the newest sample, so the plot is current even when thinned.
      if ((m - 1) * step !== n - 1 && m > 0) {
        const idx = (this.rHead - 1 + this.recentCapacity) % this.recentCapacity;
        times.push(this.rt[idx]);
        for (let c = 0; c < this.columns; c++) cols[c].push(gap(this.rv[c][idx]));
      }
    } else {
      const t0 = this.lastT - spanS;
      let first = 0;
      while (first < this.hLen && this.ht[first] < t0) first++;
      const n = this.hLen - first;
      const step = Math.max(1, Math.ceil(n / maxPoints));
      times = [];
      cols = Array.from({ length: this.columns }, () => []);
      for (let k = first; k < this.hLen; k += step) {
        times.push(this.ht[k]);
        for (let c = 0; c < this.columns; c++) cols[c].push(gap(this.hv[c][k]));
      }
      if (this.rLen > 0 && times[times.length - 1] !== this.lastT) {
        const idx = (this.rHead - 1 + this.recentCapacity) % this.recentCapacity;
        times.push(this.rt[idx]);
        for (let c = 0; c < this.columns; c++) cols[c].push(gap(this.rv[c][idx]));
      }
    }
    return [times, ...cols];
  }
}

function toNumber(v) {
  return typeof v === 'number' && Number.isFinite(v) ? v : NaN;
}

// uPlot draws null as a gap; NaN would spoil its automatic scale range.
function gap(v) {
  return Number.isNaN(v) ? null : v;
}

/** A bounded list (event log, alarms): keeps the newest `capacity` items. */
export class BoundedList {
  constructor(capacity) {
    this.capacity = capacity;
    this.items = [];
    this.dropped = 0;
  }
  push(item) {
    this.items.push(item);
    if (this.items.length > this.capacity) {
      // Drop in chunks so that a long run costs amortised O(1) per item, not a shift per push.
      const excess = Math.max(1, Math.floor(this.capacity / 4));
      this.items.splice(0, excess);
      this.dropped += excess;
    }
  }
  clear() { this.items = []; this.dropped = 0; }
}
