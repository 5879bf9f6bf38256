#!/usr/bin/env bash
# The service an operator uses: installs the Debian packages, builds, and starts imucald on the
# simulated bench (in-process simulated table, chamber and IMU), with its data (SQLite) in ./data.
# It prints the address to open in a browser and, the first time, a one-time operator token to
# sign in with; Ctrl-C stops it cleanly (the table parked, the recording flushed). Arguments go to
# imucald (docs/daemon.md), e.g. `./scripts/run.sh --listen 0.0.0.0:8080 --config lab.json`.
# IMUCAL_RUN_PREBUILT=DIR skips installing and building and runs DIR/imucald (the suite's test).
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ -n "${IMUCAL_RUN_PREBUILT:-}" ]]; then
  bin="$IMUCAL_RUN_PREBUILT"
else
  bash scripts/install-deps.sh
  # ccache keys on relative paths under the checkout, so a fresh clone reuses earlier compilations.
  export CCACHE_BASEDIR="$PWD"
  cmake --preset release >/dev/null
  cmake --build --preset release -j "$(nproc)" --target imucald imucal
  bin=build/release/bin
fi
echo "imucald on the simulated bench; Ctrl-C stops it"
# exec: Ctrl-C (SIGINT) and systemd's SIGTERM reach imucald itself, which shuts down in order.
exec "$bin/imucald" "$@"
