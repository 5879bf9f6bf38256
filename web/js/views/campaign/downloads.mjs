// What a campaign's results offer to take away: the model JSON in either frame, the certificate
// (or, for a partial run, an operator's acceptance first), the test report, the recording bundle
// and the campaign record.
import { get, post } from '../../api.mjs';
import { h, FINAL_STATES } from '../../format.mjs';
import { confirmDialog } from '../../dialogs.mjs';
import { isOperator } from '../../session.mjs';

/** The row of downloads for campaign d. getDetail() gives the campaign as last read (for its
 *  record), onError(text) says what failed, onAccepted() after an operator accepted a partial run. */
export function downloads(d, { id, getDetail, isStopped, onError, onAccepted }) {
  const element = h('div', { class: 'downloads', id: 'downloads' });
  if (d.has_model) {
    element.append(
      h('a', { class: 'button primary', id: 'download-model', href: `/api/campaigns/${id}/model`, download: `campaign-${id}-model-instrument.json` }, 'Model JSON (instrument frame)'),
      h('a', { class: 'button', id: 'download-model-body', href: `/api/campaigns/${id}/model?frame=body`, download: `campaign-${id}-model-body.json` }, 'Model JSON (body frame)'),
      certificateControl(d, { id, onError, onAccepted }));
  } else {
    element.append(h('span', { class: 'muted', id: 'no-model' }, d.state === 'done' ? 'This campaign produced no model (see the estimator notes below).' : `No model: the campaign ended ${d.state}.`));
  }
  const bundle = h('a', { class: 'button', id: 'download-recording', 'aria-disabled': 'true' }, 'Recording bundle (tar)');
  if (Object.keys(d.results || {}).length)
    element.append(h('a', { class: 'button', id: 'test-report', href: `report.html?id=${id}`, target: '_blank', rel: 'noopener' }, 'Test report (print)'));
  element.append(bundle, h('button', { type: 'button', class: 'link', id: 'download-record', onclick: () => saveJson(`campaign-${id}.json`, getDetail()) }, 'Campaign record (JSON)'));
  recordingLink(bundle, id, d, { isStopped, onError });
  return element;
}

// The certificate of a run that counts as a calibration; for a partial run, its acceptance first
// (an operator's, with a reason: it is kept with the run and in the audit trail).
function certificateControl(d, { id, onError, onAccepted }) {
  const link = h('a', { class: 'button', id: 'certificate', href: `certificate.html?id=${id}`, target: '_blank', rel: 'noopener' }, 'Calibration certificate (print)');
  if (d.complete || d.accepted) return link;
  const note = h('span', { class: 'muted', id: 'not-accepted' }, 'Partial run, not accepted: no certificate is issued until an operator accepts it.');
  if (!isOperator()) return note;
  const accept = h('button', { type: 'button', id: 'accept-partial' }, 'Accept as calibration…');
  accept.addEventListener('click', async () => {
    const answer = await confirmDialog({
      title: `Accept campaign ${id} as its unit's calibration?`,
      body: [`It ended ${d.state} at ${Math.round(100 * (d.progress || 0))} % of its program. Accepted, it counts as a calibration and its certificate is issued, stating the partial run and your reason.`],
      confirmLabel: 'Accept', reason: true,
    });
    if (!answer.ok) return;
    if (!answer.reason) {
      onError('Not accepted: say why the partial run is good enough (the reason is kept with the run).');
      return;
    }
    try {
      await post(`/api/campaigns/${id}/accept`, { reason: answer.reason });
      await onAccepted();
    } catch (e) {
      onError(`Not accepted: ${e.message}`);
    }
  });
  return h('span', {}, note, ' ', accept);
}

// The recording bundle's link (GET .../recording, a tar): written from the run file once the run
// has ended, by a job on imucald (202 with its progress until the file is there). A click asks
// until then, showing how far it is, and then lets the browser download the file itself.
function recordingLink(link, id, detail, { isStopped, onError }) {
  const url = `/api/campaigns/${id}/recording`;
  if (!detail.run_db || !FINAL_STATES.has(detail.state)) {
    link.title = detail.run_db ? 'Available when the run has ended.' : 'This campaign was never started: there is no recording.';
    link.classList.add('disabled');
    return;
  }
  link.href = url;
  link.setAttribute('download', `campaign-${id}-recording.tar`);
  link.removeAttribute('aria-disabled');
  link.title = 'imucal-recording/1 bundle (meta.json, frames.csv, program.json, truth.json) as one tar file; unpack and read it with "imucal import DIR"';
  link.addEventListener('click', (event) => {
    if (link.dataset.ready === 'true') return;  // the click below: the browser downloads
    event.preventDefault();
    if (link.dataset.preparing !== 'true') prepareRecording(link, url, { isStopped, onError });
  });
}

async function prepareRecording(link, url, { isStopped, onError }) {
  const label = link.textContent;
  link.dataset.preparing = 'true';
  try {
    await get(url, { discardBody: true, onPending: (p) => {
      if (isStopped()) return false;
      link.dataset.progress = String(p?.progress ?? 0);
      link.textContent = p?.state === 'queued' ? 'Recording bundle: queued behind other jobs…'
        : `Recording bundle: writing… ${Math.round(100 * (p?.progress ?? 0))} %`;
      return true;
    } });
    if (isStopped()) return;
    link.textContent = label;
    link.dataset.ready = 'true';
    link.click();
  } catch (e) {
    if (isStopped()) return;
    link.textContent = label;
    onError(`The recording bundle could not be written: ${e.message}`);
  } finally {
    delete link.dataset.preparing;
    delete link.dataset.ready;
  }
}

function saveJson(filename, data) {
  const url = URL.createObjectURL(new Blob([JSON.stringify(data, null, 1)], { type: 'application/json' }));
  const a = h('a', { href: url, download: filename });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}
