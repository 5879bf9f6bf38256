// The sign-in page: operator or viewer, with a password or a token (docs/api.md, "Authentication").
import { h } from '../format.mjs';
import { session, signInForm } from '../session.mjs';

export function mount(root, ctx) {
  const form = signInForm({
    onSuccess: () => {
      const next = ctx.afterSignIn();
      ctx.navigate(next && next !== '#/signin' ? next : '#/campaigns');
    },
  });
  root.append(h('section', { class: 'signin card' },
    h('h1', {}, 'Sign in to imucal'),
    h('p', { class: 'lead' }, 'Operators launch and stop calibration campaigns; viewers see everything and change nothing.'),
    session.user ? h('p', { class: 'hint' }, `You are signed in as ${session.user} (${session.role}). Sign in again to switch user, or `,
      h('a', { href: '#/campaigns' }, 'go to the campaigns'), '.') : null,
    form));
  form.focusFirst();
  return null;
}
