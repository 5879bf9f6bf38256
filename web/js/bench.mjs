// What bench this is, for the first screen (issue 36, item 9): simulated or real, which devices,
// connected or not, from GET /api/status (`devices`, `site`) and the live telemetry's `table`,
// `chamber` and `imu` blocks (docs/api.md). No DOM.

// docs/api.md: `devices` is sim, sim-wire, or real when the configuration names the devices.
const KINDS = {
  sim: { simulated: true, title: 'Simulated bench',
    text: 'The rate table, the thermal chamber and the IMU are simulated inside imucald, in accelerated time; nothing moves.' },
  'sim-wire': { simulated: true, title: 'Simulated bench on the wire',
    text: 'The simulated table, chamber and IMU speak the real protocols on loopback, through the real drivers, in real time; nothing moves.' },
  real: { simulated: false, title: 'Real bench',
    text: 'The rate table, the chamber and the IMU named in imucald\'s configuration. Starting a campaign moves the table.' },
};

// One device's state from its telemetry block: connected or not, and a word on what it does.
// `detail` gives its words, a warning among them as {warn: text} (a table not homed yet).
function deviceState(block, detail) {
  if (!block) return { state: 'unknown', text: 'no reading yet' };
  if (block.connected === false) return { state: 'bad', text: 'not connected' };
  const words = detail(block).filter(Boolean);
  const warn = words.some((w) => typeof w === 'object');
  return { state: warn ? 'warn' : 'ok', text: ['connected', ...words.map((w) => (typeof w === 'object' ? w.warn : w))].join(', ') };
}

/**
 * {simulated, title, text, site, devices: [{name, state: ok|warn|bad|unknown, text}]}; `status` GET
 * /api/status, `telemetry` the newest live message (or null before the first).
 */
export function benchSummary(status, telemetry) {
  const kind = KINDS[status?.devices] || { simulated: false, title: `Bench "${status?.devices ?? 'unknown'}"`, text: '' };
  const t = telemetry || {};
  const fixed1 = (v) => (typeof v === 'number' && Number.isFinite(v) ? v.toFixed(1) : null);
  return {
    simulated: kind.simulated,
    title: kind.title,
    text: kind.text,
    site: status?.site?.name || null,
    devices: [
      { name: 'Rate table', ...deviceState(t.table, (b) => [b.homed === false ? { warn: 'not homed yet (a run homes it first)' } : b.homed ? 'homed' : null,
        b.fault ? { warn: `fault: ${b.fault}` } : null]) },
      { name: 'Chamber', ...deviceState(t.chamber, (b) => [fixed1(b.temperature_C) !== null ? `${fixed1(b.temperature_C)} °C` : null]) },
      // The IMU's frame figures belong to a run (between runs they are the last run's).
      { name: 'IMU', ...deviceState(t.imu, (b) => [t.run && b.frame_rate_hz > 0 ? `${fixed1(b.frame_rate_hz)} frames/s` : null]) },
    ],
  };
}
