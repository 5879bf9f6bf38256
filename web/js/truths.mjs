// The simulated IMU's truth in the builder (no DOM): the truths imucald offers by name (GET
// /api/status, limits.campaign.truths), the one a new campaign starts with, and a truth JSON file
// uploaded from the operator's computer, checked before it is sent inline with the campaign.

/** The truth the builder starts with: the realistic navigation-grade unit when imucald offers it. */
export const PREFERRED_TRUTH = 'nav-grade';

/** The names to offer, "ideal" always among them: [{name, description, builtin}]. */
export function truthChoices(truths) {
  const list = Array.isArray(truths) ? truths.filter((t) => t && typeof t.name === 'string') : [];
  if (!list.some((t) => t.name === 'ideal')) list.unshift({ name: 'ideal', description: 'an error-free, noise-free IMU', builtin: true });
  return list;
}

/** A new campaign's truth: nav-grade when offered, else the first named one that is not ideal, else ideal. */
export function defaultTruth(truths) {
  const list = truthChoices(truths);
  if (list.some((t) => t.name === PREFERRED_TRUTH)) return PREFERRED_TRUTH;
  return 'ideal';
}

/** The largest truth file the builder sends (imucald's truths folder reads at most 1 MiB too). */
export const MAX_TRUTH_BYTES = 1 << 20;

/**
 * A truth file's text as the model to send inline: {model} or {error}. Checks what the page can:
 * JSON, an imucal-imu-model/1 object, written in the instrument frame (imucald checks the rest).
 */
export function parseTruthFile(text, fileName = 'the file') {
  if (typeof text !== 'string' || !text.trim()) return { error: `${fileName} is empty.` };
  if (text.length > MAX_TRUTH_BYTES) return { error: `${fileName} is larger than 1 MiB.` };
  let model;
  try {
    model = JSON.parse(text);
  } catch (e) {
    return { error: `${fileName} is not JSON: ${e.message}` };
  }
  if (!model || typeof model !== 'object' || Array.isArray(model)) return { error: `${fileName} is not a JSON object.` };
  if (model.format !== 'imucal-imu-model/1')
    return { error: `${fileName} is not an IMU model: "format" must be "imucal-imu-model/1" (docs/formats.md).` };
  if (model.frame !== undefined && model.frame !== 'instrument')
    return { error: `${fileName} is in the ${model.frame} frame: a truth is written in the instrument frame.` };
  return { model };
}

/** How the builder names a truth it shows: a name, or the model uploaded and sent inline. */
export function truthLabel(truth) {
  if (typeof truth === 'string') return truth;
  if (truth && typeof truth === 'object') return 'a model uploaded from this computer (sent inline with the campaign)';
  return 'ideal';
}
