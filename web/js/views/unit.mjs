// One unit's page (issue 17): its calibrations from the registry (GET /api/imus/{serial}), partial
// runs marked as such, each one's verdict against its part number's limits and its change since
// the previous calibration in sigmas, a chosen coefficient over the calibrations as a trend with
// its sigma, the turn-on to turn-on repeatability, and two calibrations side by side
// (GET /api/compare).
import { get, post } from '../api.mjs';
import { confirmDialog } from '../dialogs.mjs';
import { isOperator } from '../session.mjs';
import { h, clear, dateTime, outcomeBadge, num } from '../format.mjs';
import { verdictBadge } from './units.mjs';
import { lineChart, COLORS } from '../plots.mjs';
import { flatten, orderOf, unitOf } from '../coefficients.mjs';

export function mount(root, ctx) {
  const serial = ctx.params.serial;
  const url = `/api/imus/${encodeURIComponent(serial)}`;
  const status = h('div', { class: 'form-error', role: 'alert', id: 'unit-error' });
  const info = h('p', { class: 'muted', id: 'unit-info' });
  // Certificates in force issued with a site g the configuration has since corrected (imucald's
  // gravity_corrected): they stand on the old value until calibrated again and reissued.
  const gravityNote = h('div', { class: 'form-error', id: 'unit-gravity-corrected', hidden: true });
  const body = h('tbody', { id: 'unit-calibrations' });
  const select = h('select', { id: 'unit-coefficient' });
  const plotBox = h('div', { class: 'plot', id: 'unit-trend' });
  const repeatBody = h('tbody', { id: 'unit-repeatability' });
  const pickA = h('select', { id: 'compare-a' });
  const pickB = h('select', { id: 'compare-b' });
  const compareOut = h('div', { id: 'unit-compare' });
  let chart = null;
  let calibrations = [];

  root.append(
    h('div', { class: 'page-head' }, h('h1', {}, `Unit ${serial}`),
      h('div', { class: 'actions' },
        h('a', { class: 'button', id: 'unit-csv', href: `${url}/history.csv`, download: `imu-${serial}-history.csv` }, 'History (CSV)'))),
    status, info, gravityNote,
    h('section', { class: 'card' }, h('h2', {}, 'Calibrations'),
      h('table', { class: 'list', id: 'unit-table' },
        h('thead', {}, h('tr', {}, h('th', { class: 'num' }, '#'), h('th', {}, 'Name'), h('th', {}, 'Program'),
          h('th', {}, 'Ended'), h('th', {}, 'State'), h('th', {}, 'Counts as a calibration'), h('th', {}, 'Verdict'),
          h('th', {}, 'Change since the previous'))),
        body)),
    h('section', { class: 'card' }, h('h2', {}, 'Trend'),
      h('div', { class: 'actions' }, h('label', { for: 'unit-coefficient' }, 'Coefficient'), select),
      h('p', { class: 'hint' }, 'Each calibration with a model, oldest first; the band is ±1 sigma.'), plotBox),
    h('section', { class: 'card' }, h('h2', {}, 'Two calibrations side by side'),
      h('div', { class: 'actions' }, h('label', { for: 'compare-a' }, 'From'), pickA, h('label', { for: 'compare-b' }, 'to'), pickB,
        h('button', { type: 'button', id: 'compare-go', onclick: () => compare() }, 'Compare')),
      h('p', { class: 'hint' }, 'A difference is significant beyond 3 combined sigmas (the two runs\' 1σ added in quadrature).'),
      compareOut),
    h('section', { class: 'card' }, h('h2', {}, 'Repeatability'),
      h('p', { class: 'hint' }, 'Turn-on to turn-on (IEEE Std 952): the sample standard deviation of each coefficient over the calibrations that count and determined it.'),
      h('table', { class: 'list' }, h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, 'Runs'),
        h('th', { class: 'num' }, 'Mean'), h('th', { class: 'num' }, 'Standard deviation'), h('th', {}, 'Unit'))), repeatBody)));

  select.addEventListener('change', () => plot(select.value));

  function counts(c) {
    if (c.counts && c.complete) return 'yes';
    if (c.counts) return `yes, partial run accepted: ${c.accepted?.reason || ''}`;
    if (!c.model) return 'no: no model';
    return `no: partial (${Math.round(100 * (c.progress || 0))} % of the program), not accepted`;
  }

  function verdictCell(v) {
    if (!v) return verdictBadge(null);
    const failing = v.coefficients.filter((c) => !c.pass);
    return h('span', {}, verdictBadge(v.pass, failing.map((c) => `${c.key}: ${c.reason}`).join('\n')),
      failing.length ? h('span', { class: 'small' }, ` ${failing.map((c) => `${c.key}: ${c.reason}`).join('; ')}`) : '');
  }

  function changeCell(ch) {
    if (!ch) return '—';
    const values = Object.values(ch.in_sigmas || {});
    const largest = values.length ? Math.max(...values.map(Math.abs)) : null;
    return h('span', { class: ch.significant.length ? 'result-bad' : '', title: Object.entries(ch.in_sigmas).map(([k, v]) => `${k}: ${num(v, 2)} σ`).join('\n') },
      ch.significant.length ? `${ch.significant.length} significant (${ch.significant.join(', ')})` : 'none significant',
      largest !== null ? `, largest ${num(largest, 2)} σ` : '');
  }

  async function compare() {
    if (!pickA.value || !pickB.value) return;
    clear(compareOut).append(h('p', { class: 'muted' }, 'Comparing…'));
    try {
      const c = await get(`/api/compare?a=${pickA.value}&b=${pickB.value}`);
      const rows = c.coefficients.slice().sort((x, y) => orderOf(x.key) - orderOf(y.key) || x.key.localeCompare(y.key));
      const sig = (s) => (s == null ? '' : ` ± ${num(s, 2)}`);
      clear(compareOut).append(
        h('p', { id: 'compare-summary' }, `${c.significant} significant difference${c.significant === 1 ? '' : 's'} between #${c.a.campaign_id} and #${c.b.campaign_id}.`),
        h('table', { class: 'list', id: 'compare-table' },
          h('thead', {}, h('tr', {}, h('th', {}, 'Coefficient'), h('th', { class: 'num' }, `#${c.a.campaign_id}`), h('th', { class: 'num' }, `#${c.b.campaign_id}`),
            h('th', { class: 'num' }, 'Difference'), h('th', { class: 'num' }, 'In combined σ'), h('th', {}, 'Unit'))),
          h('tbody', {}, ...rows.map((r) => h('tr', { class: r.significant ? 'result-bad' : '', dataset: { key: r.key } },
            h('td', {}, r.key), h('td', { class: 'num' }, `${num(r.a, 5)}${sig(r.sigma_a)}`), h('td', { class: 'num' }, `${num(r.b, 5)}${sig(r.sigma_b)}`),
            h('td', { class: 'num' }, num(r.difference, 3)), h('td', { class: 'num' }, r.in_sigmas == null ? '—' : num(r.in_sigmas, 2)),
            h('td', {}, unitOf(r.key)))))));
    } catch (e) {
      clear(compareOut).append(h('p', { class: 'form-error' }, `Cannot compare: ${e.message}`));
    }
  }

  function plot(name) {
    const points = calibrations.filter((c) => c.model);
    const values = points.map((c) => flatten(c.model).get(name) ?? null);
    const sigmas = points.map((c) => (c.model.sigma ? flatten(c.model.sigma).get(name) ?? null : null));
    const hi = values.map((v, i) => (v == null || sigmas[i] == null ? null : v + sigmas[i]));
    const lo = values.map((v, i) => (v == null || sigmas[i] == null ? null : v - sigmas[i]));
    if (chart) chart.destroy();
    clear(plotBox);
    chart = lineChart(plotBox, { title: `${name} [${unitOf(name)}]`, x: 'calibration', xIntegers: true, y: unitOf(name), height: 220, points: true,
      series: [{ label: 'value', color: COLORS[0] }, { label: '+1σ', band: true }, { label: '−1σ', band: true }],
      bands: [[2, 3, 'rgba(21,101,192,0.15)']] });
    chart.setData([points.map((_, i) => i + 1), values, hi, lo]);
  }

  // An operator has the run calibrated again from its recording with the corrected g (a job on
  // imucald, polled); its new certificate supersedes the one listed.
  function recalibrateButton(c) {
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

  (async () => {
    try {
      const u = await get(url);
      calibrations = u.calibrations || [];
      const corrected = u.gravity_corrected || [];
      gravityNote.hidden = corrected.length === 0;
      gravityNote.replaceChildren(...(corrected.length ? [
        'The site\'s g has been corrected since these certificates were issued with the old value: ',
        ...corrected.flatMap((c, i) => [i ? ', ' : '',
          h('a', { href: `certificate.html?number=${encodeURIComponent(c.number)}` }, c.number),
          ` (campaign ${c.campaign_id}, g ${num(c.issued_with_mps2, 9)} → ${num(c.now_mps2, 9)} m/s²)`,
          ...(isOperator() ? [' ', recalibrateButton(c)] : [])]),
        '.'] : []));
      info.textContent = `${u.part_number ? `Part number ${u.part_number}${u.limits ? ` (limits from ${u.limits})` : ', no acceptance limits'}. ` : ''}${u.calibrations_counted} calibration${u.calibrations_counted === 1 ? '' : 's'} counted of ${calibrations.length} ended campaign${calibrations.length === 1 ? '' : 's'}.`;
      clear(body).append(...calibrations.map((c) => h('tr', { dataset: { id: c.campaign_id, complete: String(c.complete) } },
        h('td', { class: 'num' }, h('a', { href: `#/campaigns/${c.campaign_id}` }, c.campaign_id)),
        h('td', {}, c.name), h('td', {}, c.program), h('td', {}, dateTime(c.date)),
        h('td', {}, outcomeBadge(c)),
        h('td', {}, counts(c)), h('td', {}, verdictCell(c.verdict)), h('td', {}, changeCell(c.change)))));
      const withModel = calibrations.filter((c) => c.model);
      const option = (c) => h('option', { value: c.campaign_id }, `#${c.campaign_id} ${c.name} (${dateTime(c.date)})`);
      clear(pickA).append(...withModel.map(option));
      clear(pickB).append(...withModel.map(option));
      if (withModel.length >= 2) {
        pickA.value = String(withModel[withModel.length - 2].campaign_id);
        pickB.value = String(withModel[withModel.length - 1].campaign_id);
      }
      const rep = Object.entries(u.repeatability || {}).sort(([a], [b]) => orderOf(a) - orderOf(b) || a.localeCompare(b));
      clear(repeatBody).append(...rep.map(([k, r]) => h('tr', { dataset: { key: k } }, h('td', {}, k), h('td', { class: 'num' }, r.n),
        h('td', { class: 'num' }, num(r.mean, 5)), h('td', { class: 'num' }, num(r.std, 3)), h('td', {}, unitOf(k)))));
      if (!rep.length) repeatBody.append(h('tr', {}, h('td', { colspan: 5, class: 'muted' }, 'Needs two calibrations that count.')));
      const names = new Set();
      for (const c of calibrations) if (c.model) for (const n of flatten(c.model).keys()) names.add(n);
      const sorted = [...names].sort((a, b) => orderOf(a) - orderOf(b) || a.localeCompare(b));
      clear(select).append(...sorted.map((n) => h('option', { value: n }, `${n} [${unitOf(n)}]`)));
      if (sorted.length) plot(sorted[0]);
    } catch (e) {
      status.textContent = `Cannot load unit ${serial}: ${e.message}`;
    }
  })();

  return () => { if (chart) chart.destroy(); };
}
