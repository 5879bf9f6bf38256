#!/usr/bin/env bash
# Installs the dependencies, builds the release and sanitizer presets, and runs every test:
# the release build runs all of them (including those labelled slow), the asan build all but slow.
# Exits non-zero when any test fails or the static check (scripts/static-check.sh) finds anything.
# Warnings are errors in both presets.
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

# The release tests leave much of a core idle (devices in real time, the browser, kill -9 loops:
# they used 121 % of two cores over 15 min on 2026-11-27), so the sanitizer build runs beside them
# at the lowest priority: it takes the idle time and little else (nice works among the processes
# of this one session). Its output goes to a log, shown when it fails.
cmake --preset asan
asan_log=build/asan-build.log
set -m  # the build in a process group of its own, so that a failure here stops all of it
nice -n 19 cmake --build --preset asan -j "$jobs" >"$asan_log" 2>&1 &
asan_build=$!
trap 'kill -- -"$asan_build" 2>/dev/null || true' EXIT
# The static check (scripts/static-check.sh: lifetimes, moves, optionals) beside them too, at the same
# priority; it needs a configured tree only, no build.
static_log=build/static-check.log
nice -n 19 bash scripts/static-check.sh >"$static_log" 2>&1 &
static_check=$!
trap 'kill -- -"$asan_build" -"$static_check" 2>/dev/null || true' EXIT
ctest --preset release
if ! wait "$static_check"; then
  tail -n 60 "$static_log"
  echo "test.sh: the static check failed (whole log: $static_log)"
  exit 1
fi
echo "test.sh: static check passed ($(tail -n 1 "$static_log"))"
if ! wait "$asan_build"; then
  tail -n 60 "$asan_log"
  echo "test.sh: the sanitizer build failed (whole log: $asan_log)"
  exit 1
fi
trap - EXIT
echo "test.sh: sanitizer build done (log: $asan_log)"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ctest --preset asan
echo "imucal: all tests passed"
