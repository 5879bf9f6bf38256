// Creating the builder's campaign (POST /api/campaigns) and, asked first, starting it: then to
// its page, or to the live view when it runs at once.
import { get, post, ApiError } from '../../api.mjs';
import { duration } from '../../format.mjs';
import { confirmDialog, startCampaign } from '../../dialogs.mjs';
import { campaignBody, clientProblems, forgetDraft } from './draft.mjs';

/** check: the check panel (say, render, updateRoleUi, disableButtons); navigate(hash). */
export async function submitCampaign(andStart, { state, check, navigate }) {
  check.say('');
  const local = clientProblems(state.draft, state.fieldErrors);
  if (local.length) {
    check.say('Fix the marked fields first.');
    return;
  }
  const b = campaignBody(state.draft);
  if (andStart) {
    const scale = b.time_scale;
    const d = state.validation.duration_s;
    const answer = await confirmDialog({
      title: `Create and start "${b.name}"?`,
      body: [`The table will move as soon as the devices are free: ${typeof b.program === 'string' ? `program "${b.program}"` : `an edited program (${state.draft.program.segments.length} segments)`}, ${duration(d)} of program time${scale > 0 ? ` (about ${duration(d / scale)} at ×${scale})` : ''}.`,
        `Chamber: ${b.chamber?.setpoint_C !== undefined ? `${b.chamber.setpoint_C} °C ± ${b.chamber.tolerance_C ?? '?'} °C` : 'the safe set point'}${b.chamber?.steps?.length ? `, then ${b.chamber.steps.length} set-point step(s)` : ''}.`,
        'Make sure nobody is near the table and the IMU is mounted and cabled.'],
      confirmLabel: 'Start — the table will move', reason: false });
    if (!answer.ok) return;
  }
  check.disableButtons();
  try {
    const created = await post('/api/campaigns', b);
    forgetDraft();
    if (andStart) {
      // (Reference equipment past its due date: the operator is asked for the override's reason.)
      const started = await startCampaign(created.id, '').catch(() => null);
      if (!started) {
        navigate(`#/campaigns/${created.id}`);
        return;
      }
      // Another campaign on the bench: this one waits in the queue, and its own page says so
      // (the live view would show the other run).
      const status = await get('/api/status').catch(() => null);
      const other = status?.active && status.active.id !== created.id;
      navigate(other ? `#/campaigns/${created.id}` : '#/live');
    } else {
      navigate(`#/campaigns/${created.id}`);
    }
  } catch (e) {
    // 400/422: every problem, inline and in the panel, just as from the check.
    if (e instanceof ApiError && e.problems.length) {
      const validation = state.validation;
      state.validation = { state: 'invalid', problems: e.problems, duration_s: validation.duration_s, segments: validation.segments };
      check.render();
    }
    check.say(`imucald refused the campaign: ${e.message}`);
    check.updateRoleUi();
  }
}
