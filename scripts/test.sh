#!/usr/bin/env bash
# Installs the dependencies, builds the release and sanitizer presets, and runs every test:
# the release build runs all of them (including those labelled slow), the asan build all but slow.
# Exits non-zero when any test fails. Warnings are errors in both presets.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
# ccache keys on relative paths under the checkout, so a fresh clone reuses earlier compilations.
export CCACHE_BASEDIR="$PWD"
jobs=$(nproc)

# The browser tests' npm packages (playwright-core, uplot) from tests/browser/package-lock.json:
# nothing to do when node_modules already matches the lock; the registry is needed the first time.
# Not fatal here: without them the browser tests fail and say why, the others still run.
node tests/browser/npm-ci.mjs || echo "test.sh: npm ci failed in tests/browser; the browser tests will fail"

cmake --preset release
cmake --build --preset release -j "$jobs"
ctest --preset release

cmake --preset asan
cmake --build --preset asan -j "$jobs"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ctest --preset asan
echo "imucal: all tests passed"
