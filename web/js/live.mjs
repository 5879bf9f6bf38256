// The WebSocket /api/live (docs/api.md) and what the page keeps of it. One connection for the
// whole page, opened after sign-in and kept while the user moves between views, so the live plots
// show the run so far when the live view is opened again.
//
// Reconnection: a closed socket, or one that has been silent for several telemetry periods, is
// replaced after a back-off (0.5 s doubling to 10 s). Between attempts GET /api/me tells a daemon
// that is down (keep trying) from a session that has ended (api.mjs asks the user to sign in).
import { get, ApiError } from './api.mjs';
import { Series, BoundedList } from './series.mjs';

const AXES = ['outer', 'middle', 'inner'];
// The close code imucald uses when the session that opened the socket has ended (docs/api.md).
export const SESSION_ENDED = 4001;
export { AXES };

export class LiveClient extends EventTarget {
  constructor(path = '/api/live') {
    super();
    this.path = path;
    this.ws = null;
    this.state = 'idle';  // idle | connecting | open | waiting (to reconnect) | signin (session ended) | stopped
    this.attempt = 0;
    this.retryAt = 0;
    this.lostAt = null;   // when the connection was lost (ms), null while fine
    this.lastMessageAt = 0;
    this.telemetryHz = 10;
    this.timer = null;
    this.watchdog = null;
    this.everOpened = false;
  }

  start() {
    if (this.state !== 'idle' && this.state !== 'stopped') return;
    this.connect();
    this.watchdog = setInterval(() => this.checkSilence(), 1000);
  }

  stop() {
    this.state = 'stopped';
    clearTimeout(this.timer);
    clearInterval(this.watchdog);
    if (this.ws) {
      this.ws.onclose = null;
      this.ws.close();
      this.ws = null;
    }
    this.emitStatus();
  }

  connect() {
    clearTimeout(this.timer);
    const url = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}${this.path}`;
    this.state = 'connecting';
    this.emitStatus();
    let ws;
    try {
      ws = new WebSocket(url);
    } catch {
      this.scheduleReconnect();
      return;
    }
    this.ws = ws;
    ws.onopen = () => {
      this.state = 'open';
      this.attempt = 0;
      this.lastMessageAt = Date.now();
      const wasLost = this.lostAt;
      this.lostAt = null;
      this.everOpened = true;
      this.emitStatus({ restoredAfterMs: wasLost ? Date.now() - wasLost : null });
    };
    ws.onmessage = (ev) => {
      this.lastMessageAt = Date.now();
      let msg;
      try {
        msg = JSON.parse(ev.data);
      } catch {
        return;  // not ours to judge; the next message will do
      }
      if (msg.type === 'hello' && msg.telemetry_hz > 0) this.telemetryHz = msg.telemetry_hz;
      this.dispatchEvent(new CustomEvent('message', { detail: msg }));
    };
    ws.onclose = (ev) => {
      if (this.ws !== ws) return;
      this.ws = null;
      if (this.state === 'stopped') return;
      if (this.lostAt === null) this.lostAt = Date.now();
      if (ev.code === SESSION_ENDED) {
        // imucald closed it because the session ended (sign-out, idle timeout): ask to sign in
        // again now (GET /api/me gets 401 and api.mjs shows the dialog), then reconnect.
        this.state = 'signin';
        this.emitStatus();
        this.probeThenConnect();
        return;
      }
      this.scheduleReconnect();
    };
    ws.onerror = () => {};  // onclose follows and handles it
  }

  scheduleReconnect() {
    this.attempt++;
    const delay = Math.min(10000, 500 * 2 ** Math.min(this.attempt - 1, 5));
    this.state = 'waiting';
    this.retryAt = Date.now() + delay;
    this.emitStatus();
    this.timer = setTimeout(() => this.probeThenConnect(), delay);
  }

  // A refused upgrade looks the same as a daemon that is down; /api/me tells them apart, and for
  // an ended session api.mjs shows the sign-in dialog and resolves once signed in again.
  async probeThenConnect() {
    if (this.state === 'stopped') return;
    try {
      await get('/api/me');
    } catch (e) {
      if (!(e instanceof ApiError) || e.status === 0 || e.status >= 500) {
        this.scheduleReconnect();
        return;
      }
    }
    if (this.state !== 'stopped') this.connect();
  }

  // Telemetry comes telemetryHz times a second; a socket silent for much longer is dead even if
  // the browser has not noticed (a half-open TCP connection).
  checkSilence() {
    if (this.state === 'waiting') this.emitStatus();  // the countdown
    if (this.state !== 'open' || !this.ws) return;
    const silentMs = Date.now() - this.lastMessageAt;
    if (silentMs > Math.max(5000, 20000 / this.telemetryHz)) {
      const ws = this.ws;
      ws.onclose = null;
      ws.close();
      this.ws = null;
      this.lostAt = this.lastMessageAt;
      this.scheduleReconnect();
    }
  }

  emitStatus(extra = {}) {
    this.dispatchEvent(new CustomEvent('status', { detail: { state: this.state, attempt: this.attempt,
      retryInMs: Math.max(0, this.retryAt - Date.now()), lostAt: this.lostAt, everOpened: this.everOpened, ...extra } }));
  }
}

// Estimator coefficient series are kept per run; a coefficient's estimate and sigma updates about
// once per program second, so its bound is smaller than the telemetry's.
const ESTIMATE_OPTIONS = { recentCapacity: 1500, historyCapacity: 1000 };

// Appends a sample to the named series of `map` (created on first use), unless it is not newer
// than the last one (telemetry repeats the latest progress).
function push(map, name, t, values) {
  let s = map.get(name);
  if (!s) {
    s = new Series(3, ESTIMATE_OPTIONS);
    map.set(name, s);
  }
  if (t <= s.lastTime) return;
  s.push(t, values);
}

/**
 * What the page keeps of the telemetry: the latest message, bounded series for the plots and a
 * bounded event log. Listeners get 'telemetry', 'event', 'alarm' (raised, cleared or acknowledged:
 * {change, alarm}) and 'run' (the active run changed).
 */
export class LiveStore extends EventTarget {
  constructor() {
    super();
    this.latest = null;
    this.runId = null;
    this.runName = null;
    // The run that ended last, kept until another starts: {id, name, state} (null: none seen).
    this.finished = null;
    this.lastStates = new Map();  // campaign id -> the state its last transition event gave
    const opts = { recentCapacity: 6000, historyCapacity: 2000 };  // 10 min at 10 Hz; the whole run
    this.angles = new Series(3, opts);
    this.rates = new Series(3, opts);
    // temperature, set point, set point - tolerance, set point + tolerance
    this.chamber = new Series(4, opts);
    this.frameRate = new Series(1, opts);
    // name -> {coefficients: Map(name -> Series[est, lo, hi]), innovations: Map(name -> Series[value,
    // -gate, +gate]) (stage 3), restarts: program times, latest}
    this.estimators = new Map();
    this.events = new BoundedList(500);
    this.droppedMessages = 0;
    this.messages = 0;
    this.lastSeq = null;
  }

  ingest(msg) {
    this.messages++;
    if (msg.dropped > 0) this.droppedMessages += msg.dropped;
    if (msg.type === 'telemetry') this.ingestTelemetry(msg);
    else if (msg.type === 'event') this.ingestEvent(msg);
    else if (msg.type === 'alarm') this.dispatchEvent(new CustomEvent('alarm', { detail: msg }));
  }

  ingestTelemetry(m) {
    const t = Date.parse(m.t) / 1000;
    if (!Number.isFinite(t)) return;
    const run = m.run || null;
    const id = run ? run.id : null;
    if (id !== this.runId) {
      const previous = this.runId;
      const previousName = this.runName;
      this.runId = id;
      this.runName = run ? run.name : null;
      if (id === null && previous !== null) {
        // The run ended: the page keeps it (its plots, convergence and last state, with a link to
        // its results) until another run starts; the idle bench is not drawn over it.
        this.finished = { id: previous, name: previousName, state: this.finishedState(previous) };
        // Its estimators as stored, final ones included: what its results page shows.
        this.loadProgress(previous, { final: true });
      } else {
        // One campaign's plots never carry another's: each run starts empty; the whole run
        // comes back from its recording (views/live.mjs).
        for (const s of [this.angles, this.rates, this.chamber, this.frameRate]) s.clear();
        this.estimators.clear();
        this.finished = null;
      }
      if (id !== null) this.loadProgress(id);
      this.dispatchEvent(new CustomEvent('run', { detail: { id, previous } }));
    }
    this.latest = m;
    // A finished run's plots stand as it left them (their time axis the run's).
    if (id === null && this.finished) {
      this.dispatchEvent(new CustomEvent('telemetry', { detail: m }));
      return;
    }
    const tb = m.table || {};
    if (Array.isArray(tb.angle_deg)) this.angles.push(t, tb.angle_deg);
    if (Array.isArray(tb.rate_dps)) this.rates.push(t, tb.rate_dps);
    const ch = m.chamber || {};
    if (ch.temperature_C !== undefined) {
      const tol = ch.tolerance_C ?? NaN;
      this.chamber.push(t, [ch.temperature_C, ch.setpoint_C, ch.setpoint_C - tol, ch.setpoint_C + tol]);
    }
    if (m.imu && run) this.frameRate.push(t, [m.imu.frame_rate_hz]);
    for (const [name, e] of Object.entries(m.estimators || {})) this.addEstimate(name, e);
    this.dispatchEvent(new CustomEvent('telemetry', { detail: m }));
  }

  // The last state a transition event gave the run `id` (its final one once it has ended).
  finishedState(id) {
    return this.lastStates.get(id) ?? null;
  }

  ingestEvent(m) {
    if (m.kind === 'transition' && Number.isInteger(m.campaign) && typeof m.to === 'string') {
      this.lastStates.set(m.campaign, m.to);
      if (this.lastStates.size > 50) this.lastStates.delete(this.lastStates.keys().next().value);
      if (this.finished && this.finished.id === m.campaign) this.finished.state = m.to;
    }
    this.events.push(m);
    this.dispatchEvent(new CustomEvent('event', { detail: m }));
  }

  estimator(name) {
    let e = this.estimators.get(name);
    if (!e) {
      e = { coefficients: new Map(), innovations: new Map(), restarts: [], latest: null };
      this.estimators.set(name, e);
    }
    return e;
  }

  addEstimate(name, progress) {
    const e = this.estimator(name);
    e.latest = progress;
    if (Array.isArray(progress.restart_times_s)) e.restarts = progress.restart_times_s;
    // Stage 3: the last update's innovations, each against its gate.
    const inn = progress.innovations;
    if (inn && Number.isFinite(inn.t_s))
      for (const [name, [v, gate]] of Object.entries(inn.values || {})) push(e.innovations, name, inn.t_s, [v, -gate, gate]);
    const t = progress.program_time_s;
    if (!Number.isFinite(t) || !progress.estimates) return;
    for (const [coef, pair] of Object.entries(progress.estimates)) {
      if (!Array.isArray(pair)) continue;
      const [v, sigma] = pair;
      push(e.coefficients, coef, t, [v, v - sigma, v + sigma]);
    }
  }

  // The estimates before this page connected come from /progress, so the convergence plots start
  // at the beginning of the run, not at the moment the page was opened.
  // `final`: the run has ended and what is stored is the whole of it (its last entry included).
  async loadProgress(id, { final = false } = {}) {
    try {
      const history = await get(`/api/campaigns/${id}/progress`);
      if (final ? this.finished?.id !== id : this.runId !== id) return;
      for (const [name, list] of Object.entries(history || {})) {
        if (!Array.isArray(list)) continue;
        const e = this.estimator(name);
        // While the run goes on, the live message is newer than any of the history.
        const latest = final ? null : e.latest;
        const keep = { coefficients: e.coefficients, innovations: e.innovations };
        e.coefficients = new Map();
        e.innovations = new Map();
        for (const p of list) this.addEstimate(name, p);
        if (latest) {
          e.latest = latest;
          if (Array.isArray(latest.restart_times_s)) e.restarts = latest.restart_times_s;
        }
        // Live samples that arrived while the history loaded come after it.
        for (const key of ['coefficients', 'innovations'])
          for (const [coef, s] of keep[key]) {
            const [times, a, b, c] = s.view(Infinity, Infinity);
            for (let i = 0; i < times.length; i++) push(e[key], coef, times[i], [a[i] ?? NaN, b[i] ?? NaN, c[i] ?? NaN]);
          }
      }
      this.dispatchEvent(new CustomEvent('progress', { detail: { id } }));
    } catch {
      // No history (yet): the live messages fill the plots from now on.
    }
  }
}
