// The imucald HTTP API (docs/api.md) from the browser: JSON in and out, the session cookie for
// credentials, and one rule for an expired session: the request waits while the user signs in
// again (in a dialog over the page, so nothing typed is lost) and is then sent again. A request
// that got 401 changed nothing on the server (docs/api.md, "Errors"), so sending it again is safe.

export class ApiError extends Error {
  constructor(status, body) {
    const data = body && typeof body === 'object' ? body : { error: String(body || '') };
    super(data.error || `HTTP ${status}`);
    this.status = status;
    this.body = data;
    this.problems = Array.isArray(data.problems) ? data.problems : [];
    this.state = data.state;
  }
}

let reauthenticate = null;  // async () => resolves once signed in again (set by session.mjs)
let pendingReauth = null;   // one dialog for every request that hit 401 at the same time

export function setReauthenticate(fn) {
  reauthenticate = fn;
}

/**
 * Sends a request; resolves with the parsed JSON body, rejects with ApiError (status 0 when the
 * daemon cannot be reached). With `auth: false` a 401 is returned as an error instead of asking
 * the user to sign in (the sign-in request itself, the start-up check).
 * `onPending`: for a result computed as a job (202 while it computes, docs/api.md): called with
 * the job's state and progress, and the request is sent again a second later until the answer
 * is there.
 * `discardBody`: the answer, once there, is a file the browser downloads itself (the recording
 * bundle, hundreds of MB): its body is not read, and the request resolves with null.
 */
export async function api(method, path, body, { auth = true, signal, onPending, discardBody = false } = {}) {
  const headers = { Accept: 'application/json' };
  const init = { method, headers, credentials: 'same-origin', cache: 'no-store', signal };
  // Every change says it is JSON, body or not: imucald refuses a cookie-authenticated change of
  // another type (a cross-site form could send one, docs/api.md).
  if (body !== undefined || (method !== 'GET' && method !== 'HEAD')) headers['Content-Type'] = 'application/json';
  if (body !== undefined) init.body = typeof body === 'string' ? body : JSON.stringify(body);
  let response;
  try {
    response = await fetch(path, init);
  } catch (e) {
    if (e.name === 'AbortError') throw e;
    throw new ApiError(0, { error: `cannot reach imucald (${e.message}); is it running?` });
  }
  if (discardBody && response.ok && response.status !== 202) {
    await response.body?.cancel();
    return null;
  }
  const text = await response.text();
  let data = null;
  if (text) {
    try {
      data = JSON.parse(text);
    } catch {
      data = { error: text.trim().slice(0, 300) || response.statusText };
    }
  }
  if (response.status === 401 && auth && reauthenticate) {
    if (!pendingReauth) pendingReauth = reauthenticate().finally(() => { pendingReauth = null; });
    await pendingReauth;
    return api(method, path, body, { auth, signal, onPending, discardBody });
  }
  if (response.status === 202 && onPending) {
    if (onPending(data) === false) throw new ApiError(202, { error: 'no longer wanted' });
    await new Promise((resolve) => setTimeout(resolve, 1000));
    return api(method, path, body, { auth, signal, onPending, discardBody });
  }
  if (!response.ok) throw new ApiError(response.status, data || { error: `${response.status} ${response.statusText}` });
  return data;
}

export const get = (path, options) => api('GET', path, undefined, options);
export const post = (path, body, options) => api('POST', path, body === undefined ? {} : body, options);
