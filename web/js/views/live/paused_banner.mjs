// A paused run says who paused it and how it goes on (its transitions, asked once per pause).
import { get } from '../../api.mjs';
import { h, timeOfDay } from '../../format.mjs';
import { pauseNote } from '../../outcome.mjs';

/** The banner; show(run) shows it while the run pauses (run may be null). */
export function pausedBanner() {
  const element = h('div', { class: 'suspended-banner paused-banner', id: 'paused-banner', role: 'status', hidden: true });
  let pauseFor = '';
  let pauseTransitions = null;
  let shown = null;  // the run last shown, drawn again once its transitions are in
  function show(run) {
    shown = run;
    const paused = run && (run.state === 'paused' || run.state === 'pausing');
    element.hidden = !paused;
    if (!paused) { pauseFor = ''; pauseTransitions = null; return; }
    if (pauseFor !== String(run.id)) {
      pauseFor = String(run.id);
      get(`/api/campaigns/${run.id}`).then((d) => {
        if (pauseFor === String(d.id)) { pauseTransitions = d.transitions || []; show(shown); }
      }).catch(() => { /* the banner says "Paused." and how to go on without who */ });
    }
    const text = pauseNote(pauseTransitions, timeOfDay).text;
    if (element.textContent !== text) element.textContent = text;
  }
  return { element, show };
}
