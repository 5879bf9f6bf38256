#!/usr/bin/env bash
# Installs the dependencies, builds the release and sanitizer presets, and runs every test:
# the release build runs all of them (including those labelled slow), the asan build all but slow.
# Exits non-zero when any test fails. Warnings are errors in both presets.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
jobs=$(nproc)

cmake --preset release
cmake --build --preset release -j "$jobs"
ctest --preset release

cmake --preset asan
cmake --build --preset asan -j "$jobs"
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 ctest --preset asan
echo "imucal: all tests passed"
