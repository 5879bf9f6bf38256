#!/usr/bin/env bash
# The main job until the daemon lands: install, build, then a simulated run end to end: simulate
# the stage-3 navigation program with an error-free IMU, navigate it against the table reference,
# simulate and export a short direct run as an imucal-recording/1 bundle, and print the summary.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
bin=build/release/bin
out=build/demo
rm -rf "$out" && mkdir -p "$out"
"$bin/imucal" simulate --program navigation --imu ideal --db "$out/navigation.db" --rate 1000 --duration 1800 \
  --r0-mm 30 -20 50
"$bin/imucal" navigate --db "$out/navigation.db" --out "$out/nav.csv" --summary-json "$out/summary.json"
"$bin/imucal" simulate --program direct-short --imu ideal --db "$out/direct-short.db" --rate 100
"$bin/imucal" export --db "$out/direct-short.db" --out "$out/direct-short-bundle"
echo "summary ($out/summary.json):"
cat "$out/summary.json"
