// The state the builder's cards share: what imucald offers, the draft being edited, the problems
// the page finds in its fields and imucald's last check of it.
export function builderState() {
  return {
    programs: [],
    units: [],            // GET /api/imus: the serials already known, offered as you type
    limits: null,
    devices: null,        // GET /api/status: sim, sim-wire or real
    draft: null,          // {template, modified, campaign: {...}, program: {...}}
    fieldErrors: new Map(),  // input id -> message (client-side)
    validation: { state: 'idle', problems: [], duration_s: null, segments: [] },
    destroyed: false,     // set when the page is left: answers that come later are dropped
  };
}
