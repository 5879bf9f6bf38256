// Certificates in force issued with a site g the configuration has since corrected (imucald's
// gravity_corrected): they stand on the old value until calibrated again and reissued. An
// operator has a run calibrated again from its recording with the corrected g (a job on imucald,
// polled); its new certificate supersedes the one listed.
import { post } from '../../api.mjs';
import { confirmDialog } from '../../dialogs.mjs';
import { isOperator } from '../../session.mjs';
import { h, num } from '../../format.mjs';

/** The note; show(corrected) lists the certificates; a refusal goes to status (the page's error line). */
export function gravityCorrectedNote(status) {
  const element = h('div', { class: 'form-error', id: 'unit-gravity-corrected', hidden: true });
  function show(corrected) {
    element.hidden = corrected.length === 0;
    element.replaceChildren(...(corrected.length ? [
      'The site\'s g has been corrected since these certificates were issued with the old value: ',
      ...corrected.flatMap((c, i) => [i ? ', ' : '',
        h('a', { href: `certificate.html?number=${encodeURIComponent(c.number)}` }, c.number),
        ` (campaign ${c.campaign_id}, g ${num(c.issued_with_mps2, 9)} → ${num(c.now_mps2, 9)} m/s²)`,
        ...(isOperator() ? [' ', recalibrateButton(c, status)] : [])]),
      '.'] : []));
  }
  return { element, show };
}

function recalibrateButton(c, status) {
  const button = h('button', { type: 'button', class: 'recalibrate', 'data-campaign': String(c.campaign_id) },
    'Calibrate again…');
  button.addEventListener('click', async () => {
    const answer = await confirmDialog({
      title: `Calibrate campaign ${c.campaign_id} again with the corrected g?`,
      body: [`Its stages are run again from its recording with g = ${num(c.now_mps2, 9)} m/s² (was ${num(c.issued_with_mps2, 9)}). `
        + `A new certificate states the new model and supersedes ${c.number}, which stays as issued.`],
      confirmLabel: 'Calibrate again', reason: true, reasonPlaceholder: 'required: e.g. the new survey, kept on the new certificate',
    });
    if (!answer.ok) return;
    if (!answer.reason) {
      status.textContent = 'Not calibrated again: say why (the reason is kept in the audit trail and on the new certificate).';
      return;
    }
    button.disabled = true;
    try {
      const done = await post(`/api/campaigns/${c.campaign_id}/recalibrate`, { reason: answer.reason }, {
        onPending: (p) => { button.textContent = `Calibrating… ${Math.round(100 * (p?.progress || 0))} %`; },
      });
      status.textContent = '';
      button.replaceWith(h('span', { class: 'muted' }, `→ certificate `,
        h('a', { href: `certificate.html?number=${encodeURIComponent(done.certificate.number)}` }, done.certificate.number)));
    } catch (e) {
      button.disabled = false;
      button.textContent = 'Calibrate again…';
      status.textContent = `Not calibrated again: ${e.message}`;
    }
  });
  return button;
}
