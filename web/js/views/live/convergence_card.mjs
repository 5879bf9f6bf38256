// The estimators converging on the live page: each coefficient's estimate ± σ over program time
// (convergence.mjs) for one estimator, the operator's pick among those with estimates, else the
// one running now.
import { h, clear } from '../../format.mjs';
import { convergencePanel } from '../../convergence.mjs';

/** The card; start() once it is in the page, drawPick() the estimators to pick from, update()
 *  the panel, destroy() drops the charts. */
export function convergenceCard(store) {
  const convEl = h('div', { id: 'convergence' });
  const convPick = h('div', { class: 'tabs small', role: 'tablist', id: 'conv-estimator' });
  const element = h('section', { class: 'card' }, h('div', { class: 'section-head' }, h('h2', {}, 'Estimators converging (estimate ± σ over program time)'), convPick), convEl);
  let pickedEstimator = null;
  // A draw scheduled for the next frame may come after the view was left (its elements gone).
  let destroyed = false;

  // The estimator whose convergence is shown (those with estimates: direct, lever-arm, stage3).
  function shownEstimator() {
    const withEstimates = [...store.estimators.entries()].filter(([, e]) => e.coefficients.size > 0).map(([n]) => n);
    if (pickedEstimator && withEstimates.includes(pickedEstimator)) return pickedEstimator;
    const running = withEstimates.filter((n) => store.estimators.get(n).latest?.status === 'running');
    return running.length ? running[running.length - 1] : withEstimates[withEstimates.length - 1] || null;
  }

  let conv = null;
  function start() {
    const restartsOf = (name) => store.estimators.get(name)?.restarts || [];
    conv = convergencePanel(convEl, () => {
      const name = shownEstimator();
      return name ? store.estimators.get(name).coefficients : new Map();
    }, { idPrefix: 'live-conv', markers: () => restartsOf(shownEstimator()) });
  }

  function drawPick() {
    if (destroyed) return;
    const names = [...store.estimators.entries()].filter(([, e]) => e.coefficients.size > 0).map(([n]) => n);
    const shown = shownEstimator();
    const sig = `${names.join('|')}/${shown}`;
    if (convPick.dataset.sig === sig) return;
    if (convPick.dataset.shown !== undefined && convPick.dataset.shown !== String(shown)) conv.rebuild();
    convPick.dataset.sig = sig;
    convPick.dataset.shown = String(shown);
    clear(convPick).append(...(names.length > 1 ? names : []).map((n) => h('button', {
      type: 'button', role: 'tab', dataset: { estimator: n }, 'aria-selected': String(n === shown),
      onclick: () => { pickedEstimator = n; drawPick(); } }, n)));
  }

  return {
    element, start, drawPick,
    update: () => conv.update(),
    destroy: () => { destroyed = true; conv?.destroy(); },
  };
}
