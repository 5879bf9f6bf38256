// What the run asks the operator (a power cycle of the IMU): it waits for the answer, which an
// operator gives here ("Done: the IMU is on again").
import { post } from '../../api.mjs';
import { isOperator } from '../../session.mjs';
import { h, timeOfDay } from '../../format.mjs';

/** The box; show(run) shows the run's question, or hides the box when it asks none (run may be null). */
export function runPrompt() {
  const promptText = h('p', { id: 'prompt-text' });
  const promptError = h('div', { class: 'form-error', id: 'prompt-error', role: 'alert' });
  const promptDone = h('button', { type: 'button', class: 'primary', id: 'prompt-done' }, 'Done: the IMU is on again');
  const element = h('div', { class: 'prompt-box', id: 'prompt-box', role: 'alert', hidden: true },
    h('strong', {}, 'The run waits for you'), promptText, promptDone, promptError);
  let promptRun = null;
  promptDone.addEventListener('click', async () => {
    if (promptRun === null) return;
    promptDone.disabled = true;
    promptError.textContent = '';
    try {
      await post(`/api/campaigns/${promptRun}/prompt`, { answer: 'done' });
    } catch (e) {
      promptError.textContent = `The answer was not taken: ${e.message}`;
      promptDone.disabled = !isOperator();
    }
  });
  function show(run) {
    const asked = run?.prompt || null;
    if (asked && (element.hidden || element.dataset.segment !== String(asked.segment))) {
      promptRun = run.id;
      element.dataset.segment = String(asked.segment);
      promptText.textContent = `${asked.text} (asked at ${timeOfDay(asked.since)})`;
      promptDone.disabled = !isOperator();
      promptDone.title = isOperator() ? '' : 'operator role required (you are signed in as a viewer)';
      promptError.textContent = '';
    }
    element.hidden = !asked;
  }
  return { element, show };
}
