// Copies uPlot from node_modules (pinned by package-lock.json) into web/vendor/, so that imucald
// serves the UI from the source tree with no npm step and no network: the copy is committed, and
// run.mjs fails when it differs from the locked package (run `npm run vendor` after an update).
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const from = path.join(here, 'node_modules', 'uplot');
const to = path.join(here, '..', '..', 'web', 'vendor');

export const vendoredFiles = [
  ['dist/uPlot.esm.js', 'uPlot.esm.js'],
  ['dist/uPlot.min.css', 'uPlot.min.css'],
  ['LICENSE', 'uPlot.LICENSE.txt'],
];

// Names of vendored files whose content differs from node_modules (empty: up to date).
export function staleVendoredFiles() {
  return vendoredFiles
    .filter(([src, dst]) => {
      const a = path.join(from, src), b = path.join(to, dst);
      return !fs.existsSync(b) || !fs.readFileSync(a).equals(fs.readFileSync(b));
    })
    .map(([, dst]) => dst);
}

if (process.argv[1] && path.resolve(process.argv[1]) === fileURLToPath(import.meta.url)) {
  if (!fs.existsSync(from)) {
    console.error('vendor-uplot: run `npm ci` in tests/browser first');
    process.exit(1);
  }
  fs.mkdirSync(to, { recursive: true });
  const version = JSON.parse(fs.readFileSync(path.join(from, 'package.json'), 'utf8')).version;
  for (const [src, dst] of vendoredFiles) fs.copyFileSync(path.join(from, src), path.join(to, dst));
  fs.writeFileSync(path.join(to, 'README.txt'),
    `uPlot ${version} (MIT, see uPlot.LICENSE.txt), copied from npm by tests/browser/vendor-uplot.mjs.\n` +
    'Do not edit: change the version in tests/browser/package.json and run `npm run vendor` there.\n');
  console.log(`vendor-uplot: uPlot ${version} -> ${path.relative(process.cwd(), to)}`);
}
