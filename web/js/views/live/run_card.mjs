// The live view's run card: the active run's title, state and commands, its suspension, pause and
// question to the operator, the last run's end once nothing runs, and where the run is (step,
// program time, time left, speed, progress).
import { h, clear, duration, num, stateBadge } from '../../format.mjs';
import { commandBar } from '../../dialogs.mjs';
import { runPrompt } from './run_prompt.mjs';
import { pausedBanner } from './paused_banner.mjs';

// Where the run is: its step, or, once the program has ended ahead of the estimators (a fast time
// scale), that they are finishing the rest of the recording.
function runStepText(run) {
  const seg = run.segment || {};
  return run.estimators_finishing ? 'The program has ended; the estimators are working through the rest of the recording, then its results are stored.'
    : `step ${seg.index + 1} of ${seg.count}: ${seg.name} (${seg.kind})`;
}

/** The card. draw(run, finished) shows the run (null: nothing runs, finished the last run's end);
 *  noteEvent(e) keeps a suspension's reason; onCommandDone after a command was sent. */
export function runCard({ onCommandDone }) {
  const element = h('section', { class: 'card run-card', id: 'run-card' });
  const suspendedBanner = h('div', { class: 'suspended-banner', id: 'suspended-banner', role: 'alert', hidden: true });
  const paused = pausedBanner();
  const prompt = runPrompt();
  const runTitle = h('h1', { id: 'run-title' });
  const runState = h('span', { id: 'run-state' });
  const stepText = h('div', { class: 'kv', id: 'run-step' });
  const timeText = h('div', { class: 'kv', id: 'run-time' });
  const leftText = h('div', { class: 'kv', id: 'run-left' });
  const speedText = h('div', { class: 'kv', id: 'run-speed' });
  const progress = h('div', { class: 'progress wide', id: 'run-progress' }, h('div', { class: 'bar' }), h('span', {}));
  // The run that ended, kept with its plots and convergence until another starts (issue 36).
  const finishedBox = h('p', { class: 'finished-run', id: 'finished-run', hidden: true });
  let current = null;  // {id, name, state} of the run shown
  const commands = commandBar({ getCampaign: () => current, onDone: onCommandDone });
  element.append(
    h('div', { class: 'run-head' }, runTitle, runState, h('div', { class: 'spacer' }), commands),
    suspendedBanner, paused.element, prompt.element, finishedBox,
    h('div', { class: 'run-facts' }, stepText, timeText, leftText, speedText), progress);
  let lastSuspendReason = '';

  const set = (el, text) => { if (el.textContent !== text) el.textContent = text; };
  function drawRun(run) {
    runTitle.textContent = `#${run.id} ${run.name}`;
    if (runState.dataset.state !== run.state) {
      runState.dataset.state = run.state;
      clear(runState).append(stateBadge(run.state));
    }
    set(stepText, runStepText(run));
    set(timeText, `program ${duration(run.program_time_s)} of ${duration(run.duration_s)} · checkpoint ${duration(run.checkpoint_s)}`);
    const wallLeft = run.speed_factor > 0 ? run.time_left_s / run.speed_factor : null;
    set(leftText, `time left ${duration(run.time_left_s)}${wallLeft !== null && Math.abs(run.speed_factor - 1) > 0.05 ? ` (≈ ${duration(wallLeft)} wall)` : ''}`);
    set(speedText, run.speed_factor ? `speed ×${num(run.speed_factor, 3)}` : '');
    const pct = run.duration_s > 0 ? Math.min(100, (100 * run.program_time_s) / run.duration_s) : 0;
    progress.firstChild.style.width = `${pct}%`;
    progress.lastChild.textContent = `${pct.toFixed(1)} %`;
    prompt.show(run);
    const suspended = run.state === 'suspended';
    suspendedBanner.hidden = !suspended;
    if (suspended) suspendedBanner.textContent = `Suspended${lastSuspendReason ? `: ${lastSuspendReason}` : ''}. The run resumes by itself once the condition has cleared and settled; the interrupted segment is then redone.`;
    paused.show(run);
  }

  function drawIdle() {
    runTitle.textContent = 'Nothing runs';
    clear(runState);
    runState.dataset.state = '';
    set(stepText, 'The readings below are the idle bench.');
    set(timeText, '');
    set(leftText, '');
    set(speedText, '');
    progress.firstChild.style.width = '0%';
    progress.lastChild.textContent = '';
    suspendedBanner.hidden = true;
    paused.show(null);
    prompt.show(null);
  }

  // The last run's end: what it was, how it ended, where its results are; the plots and the
  // convergence below are still its own.
  function drawFinished(fin) {
    const sig = fin ? `${fin.id}|${fin.state}|${fin.name}` : '';
    if (finishedBox.dataset.sig === sig) return;
    finishedBox.dataset.sig = sig;
    finishedBox.hidden = !fin;
    if (!fin) { finishedBox.replaceChildren(); finishedBox.dataset.campaign = ''; return; }
    finishedBox.dataset.campaign = String(fin.id);
    finishedBox.replaceChildren(`The last run, campaign ${fin.id}${fin.name ? ` (${fin.name})` : ''}, has ended`,
      fin.state ? ': ' : '.', fin.state ? stateBadge(fin.state) : '', fin.state ? '. ' : ' ',
      h('a', { href: `#/campaigns/${fin.id}`, id: 'finished-run-link' }, `See the results of campaign ${fin.id}`),
      '. The plots and the convergence below are its own until another run starts.');
  }

  function draw(run, finished) {
    current = run ? { id: run.id, name: run.name, state: run.state } : null;
    commands.update();
    if (run) drawRun(run);
    else drawIdle();
    drawFinished(run ? null : finished);
  }
  function noteEvent(e) {
    if (e.kind === 'suspended' || e.to === 'suspended') lastSuspendReason = e.reason || lastSuspendReason;
  }
  return { element, draw, noteEvent };
}
