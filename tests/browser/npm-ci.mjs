// Installs the browser tests' npm packages from package-lock.json (npm ci), only when
// node_modules does not already hold exactly that lock: idempotent and instant when up to date.
// Used by run.mjs and scripts/test.sh.
import { spawnSync } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));

export function ensureNodeModules({ quiet = false } = {}) {
  const lock = path.join(here, 'package-lock.json');
  // npm ci leaves node_modules/.package-lock.json; the copy of our lock says which one it was.
  const marker = path.join(here, 'node_modules', '.imucal-lock-copy.json');
  const installed = path.join(here, 'node_modules', '.package-lock.json');
  if (fs.existsSync(installed) && fs.existsSync(marker) && fs.readFileSync(marker).equals(fs.readFileSync(lock))) {
    if (!quiet) console.log('tests/browser: npm packages up to date');
    return true;
  }
  console.log('tests/browser: npm ci …');
  const r = spawnSync('npm', ['ci', '--no-audit', '--no-fund', '--loglevel=error'], { cwd: here, stdio: 'inherit' });
  if (r.error || r.status !== 0) {
    console.error(`tests/browser: npm ci failed${r.error ? ` (${r.error.message})` : ''}; the npm registry must be reachable the first time`);
    return false;
  }
  fs.copyFileSync(lock, marker);
  return true;
}

if (process.argv[1] && path.resolve(process.argv[1]) === fileURLToPath(import.meta.url)) {
  process.exit(ensureNodeModules() ? 0 : 1);
}
