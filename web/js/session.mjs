// Who is signed in, the sign-in form (the page and the dialog share it), and the dialog that
// appears over the current page when the session has expired: the page underneath is left
// exactly as it was, and the requests that found the session gone are sent again afterwards.
import { api, setReauthenticate, ApiError } from './api.mjs';
import { h } from './format.mjs';

export const session = { user: null, role: null, via: null, idleTimeoutS: null };
const listeners = new Set();

export function onSessionChange(fn) {
  listeners.add(fn);
  return () => listeners.delete(fn);
}

function changed() {
  document.body.dataset.role = session.role || 'none';
  for (const fn of [...listeners]) fn(session);
}

export const isOperator = () => session.role === 'operator';

/** Asks the daemon who we are; false when not signed in. */
export async function checkSession() {
  try {
    const me = await api('GET', '/api/me', undefined, { auth: false });
    Object.assign(session, { user: me.user, role: me.role, via: me.via });
    changed();
    return true;
  } catch (e) {
    if (e instanceof ApiError && e.status === 401) {
      Object.assign(session, { user: null, role: null, via: null });
      changed();
      return false;
    }
    throw e;
  }
}

export async function signIn(credentials) {
  const r = await api('POST', '/api/login', credentials, { auth: false });
  Object.assign(session, { user: r.user, role: r.role, via: 'session', idleTimeoutS: r.idle_timeout_s });
  changed();
  return r;
}

export async function signOut() {
  try {
    await api('POST', '/api/logout', {}, { auth: false });
  } finally {
    Object.assign(session, { user: null, role: null, via: null });
    changed();
  }
}

// Client-side checks, so that an obviously incomplete form is not sent (the daemon checks again).
function checkCredentials(mode, values) {
  const problems = {};
  if (mode === 'token') {
    const t = values.token.trim();
    if (!t) problems.token = 'Enter the operator token.';
    else if (/\s/.test(t)) problems.token = 'A token has no spaces; paste it exactly as imucald printed it.';
    else if (t.length < 16) problems.token = 'A token has at least 16 characters.';
  } else {
    if (!values.user.trim()) problems.user = 'Enter your user name.';
    if (!values.password) problems.password = 'Enter your password.';
  }
  return problems;
}

/**
 * The sign-in form. `onSuccess(result)` is called after the daemon accepted the credentials.
 * Two ways in: a user and password from the daemon's configuration, or an API token (e.g. the
 * one-time operator token imucald prints at its first start).
 */
export function signInForm({ onSuccess, idPrefix = 'signin' } = {}) {
  let mode = localStorage.getItem('imucal.signin.mode') === 'password' ? 'password' : 'token';
  const id = (s) => `${idPrefix}-${s}`;
  const fieldError = (name) => h('div', { class: 'field-error', id: id(`${name}-error`), role: 'alert' });

  const tokenInput = h('input', { id: id('token'), name: 'token', type: 'password', autocomplete: 'off',
    spellcheck: 'false', placeholder: 'e.g. 29fe06a5f0…', 'aria-describedby': id('token-error') });
  const userInput = h('input', { id: id('user'), name: 'user', type: 'text', autocomplete: 'username',
    'aria-describedby': id('user-error') });
  const passwordInput = h('input', { id: id('password'), name: 'password', type: 'password',
    autocomplete: 'current-password', 'aria-describedby': id('password-error') });
  const errors = { token: fieldError('token'), user: fieldError('user'), password: fieldError('password') };
  const formError = h('div', { class: 'form-error', role: 'alert', id: id('error') });
  const submit = h('button', { type: 'submit', class: 'primary', id: id('submit') }, 'Sign in');

  const tokenPane = h('div', { class: 'pane', dataset: { mode: 'token' } },
    h('label', { for: id('token') }, 'Operator or API token'),
    tokenInput, errors.token,
    h('p', { class: 'hint' },
      'At its first start imucald prints a one-time operator token (also kept in ',
      h('code', {}, 'DATA_DIR/operator-token'), '). Tokens from the configuration work too.'));
  const passwordPane = h('div', { class: 'pane', dataset: { mode: 'password' } },
    h('label', { for: id('user') }, 'User'), userInput, errors.user,
    h('label', { for: id('password') }, 'Password'), passwordInput, errors.password,
    h('p', { class: 'hint' }, 'Users and their roles (operator or viewer) come from the daemon configuration.'));

  const tabs = h('div', { class: 'tabs', role: 'tablist' });
  const setMode = (m) => {
    mode = m;
    localStorage.setItem('imucal.signin.mode', m);
    tokenPane.hidden = m !== 'token';
    passwordPane.hidden = m !== 'password';
    for (const b of tabs.children) b.setAttribute('aria-selected', String(b.dataset.mode === m));
    formError.textContent = '';
  };
  tabs.append(
    h('button', { type: 'button', role: 'tab', dataset: { mode: 'token' }, id: id('mode-token'), onclick: () => setMode('token') }, 'Token'),
    h('button', { type: 'button', role: 'tab', dataset: { mode: 'password' }, id: id('mode-password'), onclick: () => setMode('password') }, 'User and password'));

  const form = h('form', { class: 'signin-form', novalidate: true }, tabs, tokenPane, passwordPane, formError,
    h('div', { class: 'actions' }, submit));
  setMode(mode);

  form.addEventListener('submit', async (ev) => {
    ev.preventDefault();
    const values = { token: tokenInput.value, user: userInput.value, password: passwordInput.value };
    const problems = checkCredentials(mode, values);
    for (const [k, el] of Object.entries(errors)) {
      el.textContent = problems[k] || '';
      const input = { token: tokenInput, user: userInput, password: passwordInput }[k];
      input.setAttribute('aria-invalid', problems[k] ? 'true' : 'false');
    }
    formError.textContent = '';
    if (Object.keys(problems).length) return;
    submit.disabled = true;
    submit.textContent = 'Signing in…';
    try {
      const body = mode === 'token' ? { token: values.token.trim() } : { user: values.user.trim(), password: values.password };
      const r = await signIn(body);
      tokenInput.value = '';
      passwordInput.value = '';
      onSuccess?.(r);
    } catch (e) {
      formError.textContent = e.message + (e.problems?.length > 1 ? `: ${e.problems.join('; ')}` : '');
    } finally {
      submit.disabled = false;
      submit.textContent = 'Sign in';
    }
  });
  form.focusFirst = () => (mode === 'token' ? tokenInput : userInput).focus();
  return form;
}

let dialog = null;

/** Shows the sign-in dialog over the page; resolves once signed in again. */
export function signInAgain() {
  return new Promise((resolve) => {
    const previous = session.user;
    dialog?.remove();
    const form = signInForm({
      idPrefix: 'reauth',
      onSuccess: (r) => {
        dialog.close();
        dialog.remove();
        dialog = null;
        resolve(r);
      },
    });
    dialog = h('dialog', { class: 'reauth', id: 'reauth-dialog', 'aria-labelledby': 'reauth-title' },
      h('h2', { id: 'reauth-title' }, 'Please sign in again'),
      h('p', {}, previous
        ? `The session of ${previous} has ended (it expires after a while without use, and when imucald restarts). `
        : 'This needs a signed-in user. ',
        'This page keeps everything you entered; what you were doing continues after you sign in.'),
      form);
    // The dialog must not be dismissed with Escape: the waiting requests need credentials.
    dialog.addEventListener('cancel', (ev) => ev.preventDefault());
    document.body.append(dialog);
    dialog.showModal();
    form.focusFirst();
  });
}

setReauthenticate(signInAgain);
