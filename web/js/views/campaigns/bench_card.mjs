// The first screen's bench card (issue 36, item 9): what bench this is, its devices connected or
// not (bench.mjs, from imucald's status and the live telemetry), and what to do first until a
// first campaign exists.
import { h, clear } from '../../format.mjs';
import { isOperator } from '../../session.mjs';
import { benchSummary } from '../../bench.mjs';

/** The card; showFirstSteps(yes) shows or hides what to do first; destroy() stops its redraws. */
export function benchCard(ctx) {
  const element = h('section', { class: 'card bench-card', id: 'bench' });
  const firstSteps = h('ol', { class: 'first-steps', id: 'first-steps', hidden: true });
  let stopped = false;
  let daemonStatus = null;

  function draw() {
    if (stopped || !daemonStatus) return;
    const b = benchSummary(daemonStatus, ctx.store.latest);
    const sig = JSON.stringify(b);
    if (element.dataset.sig === sig) return;
    element.dataset.sig = sig;
    element.dataset.simulated = String(b.simulated);
    clear(firstSteps).append(...firstStepsFor(b).map((s) => h('li', {}, ...s)));
    clear(element).append(
      h('h2', {}, `${b.title}${b.site ? ` — ${b.site}` : ''}`),
      h('p', { class: 'bench-text' }, b.text),
      h('ul', { class: 'bench-devices', id: 'bench-devices' }, ...b.devices.map((d) =>
        h('li', { dataset: { device: d.name, state: d.state } }, h('strong', {}, d.name), ' ', h('span', { class: `flag ${['ok', 'warn', 'bad'].includes(d.state) ? d.state : ''}` }, d.text)))),
      h('h3', {}, 'What to do first'), firstSteps);
  }
  ctx.status().then((s) => { daemonStatus = s; draw(); }).catch((e) => { element.textContent = `Cannot read imucald's status: ${e.message}`; });
  // Connected or not, as the telemetry says (10 a second; the card is redrawn only on a change).
  const onTelemetry = () => draw();
  ctx.store.addEventListener('telemetry', onTelemetry);

  return {
    element,
    showFirstSteps: (yes) => { firstSteps.hidden = !yes; },
    destroy: () => {
      stopped = true;
      ctx.store.removeEventListener('telemetry', onTelemetry);
    },
  };
}

// The steps, each a list of children of its <li>: an operator's, or what a viewer can do.
function firstStepsFor(b) {
  if (!isOperator())
    return [['You are signed in as a viewer: you can watch runs on ', h('a', { href: '#/live' }, 'Live'),
      ' and read every result; an operator builds and starts campaigns.']];
  return [[h('a', { href: '#/new' }, 'New campaign'), ': start from a built-in program (', h('code', {}, 'direct-short'),
    ' is a quick first calibration: stage 1 in a few minutes of program), name the unit under test',
    b.simulated ? ' and choose the simulated IMU\'s truth' : '', '. The builder checks it with imucald and predicts its accuracy.'],
  ['"Create and start…": ', b.simulated ? 'the simulated table moves' : 'the table moves as soon as the devices are free',
    '; watch it on ', h('a', { href: '#/live' }, 'Live'), ' (pause, stop, abort there).'],
  ['When it is done, its page here has the results, the model, the certificate and the test report; ',
    h('a', { href: '#/imus' }, 'Units'), ' keeps each unit\'s calibrations and the acceptance limits.']];
}
