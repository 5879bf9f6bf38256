// The live view: the active run (step, time left, commands), table, chamber, IMU and recorder
// readings, their plots, the estimators converging, and alarms and suspensions as they happen.
// Everything comes from the page's one WebSocket through the LiveStore; this view only draws,
// once per animation frame at most. Each part is a component of views/live/; this module puts
// them on the page and passes them the store's news.
import { schedule } from '../plots.mjs';
import { equipmentBanner } from './live/equipment_banner.mjs';
import { runCard } from './live/run_card.mjs';
import { benchReadings } from './live/bench_readings.mjs';
import { livePlots } from './live/live_plots.mjs';
import { convergenceCard } from './live/convergence_card.mjs';
import { innovationsCard } from './live/innovations_card.mjs';
import { eventsCard } from './live/events_card.mjs';

export function mount(root, ctx) {
  const { store } = ctx;
  // A draw scheduled for the next frame may come after the view was left (its elements gone).
  let destroyed = false;
  const run = runCard({ onCommandDone: () => schedule(drawNumbers) });
  const readings = benchReadings();
  const equipment = equipmentBanner(ctx);
  // The due dates, the table's dialect and the chamber's register map: asked afresh, the due
  // dates are today's.
  ctx.status(true).then((s) => {
    equipment.show(s);
    readings.showStatus(s);
  }).catch(() => {});
  const plots = livePlots(store);
  const convergence = convergenceCard(store);
  const innovations = innovationsCard(store);
  const events = eventsCard();
  root.append(equipment.element, run.element, readings.element, plots.element, convergence.element,
    innovations.element, events.element);
  // The charts size themselves to their boxes, now in the page.
  plots.start();
  convergence.start();

  function drawNumbers() {
    if (destroyed) return;
    const m = store.latest;
    const current = m?.run || null;
    run.draw(current, store.finished);
    if (m) readings.draw(m, current, store);
  }
  const addEvent = (e) => {
    run.noteEvent(e);
    events.add(e);
  };

  for (const e of store.events.items) addEvent(e);
  const onTelemetry = () => {
    schedule(drawNumbers);
    schedule(plots.draw);
    schedule(convergence.drawPick);
    schedule(innovations.draw);
    convergence.update();
  };
  const onEvent = (ev) => addEvent(ev.detail);
  const onProgress = () => {
    schedule(convergence.drawPick);
    schedule(innovations.draw);
    convergence.update();
  };
  store.addEventListener('telemetry', onTelemetry);
  store.addEventListener('event', onEvent);
  store.addEventListener('progress', onProgress);
  store.addEventListener('run', plots.wholeRunMode);
  onTelemetry();
  plots.wholeRunMode();

  return () => {
    destroyed = true;
    store.removeEventListener('telemetry', onTelemetry);
    store.removeEventListener('event', onEvent);
    store.removeEventListener('progress', onProgress);
    store.removeEventListener('run', plots.wholeRunMode);
    equipment.destroy();
    plots.destroy();
    convergence.destroy();
    innovations.destroy();
  };
}
