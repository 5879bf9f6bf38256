#!/usr/bin/env bash
# The main job: install, build, then a simulated calibration end to end on the simulated table.
# A navigation-grade IMU (examples/truth-nav-grade.json) goes through the direct program (stage 1),
# the lever-arm program (size effect) and the navigation program (stage 3, 39-state filter); each
# result is compared with the truth, and the final model is judged by free-inertial navigation.
# Everything lands in build/demo/. Takes about 3 minutes on 2 cores once built.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
# ccache keys on relative paths under the checkout, so a fresh clone reuses earlier compilations.
export CCACHE_BASEDIR="$PWD"
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)" --target imucal
bin=build/release/bin
out=build/demo
truth=examples/truth-nav-grade.json
rm -rf "$out" && mkdir -p "$out"
common=(--imu "$truth" --rate 200 --r0-mm 30 -20 50 --azimuth 25)

echo "== stage 1: direct measurements"
"$bin/imucal" simulate --program direct --db "$out/direct.db" --seed 1 "${common[@]}"
"$bin/imucal" calibrate --db "$out/direct.db" --stage direct --out "$out/stage1.json"
echo "== stage 1: lever arms"
"$bin/imucal" simulate --program lever-arm --db "$out/lever-arm.db" --seed 2 "${common[@]}"
"$bin/imucal" calibrate --db "$out/lever-arm.db" --stage lever-arm --model "$out/stage1.json" --out "$out/stage1-size.json"
echo "== stage 3: refinement by the navigation solution"
"$bin/imucal" simulate --program navigation --db "$out/navigation.db" --seed 3 "${common[@]}"
"$bin/imucal" calibrate --db "$out/navigation.db" --stage navigation --model "$out/stage1-size.json" \
  --out "$out/model.json" --frame body
echo "== the calibrated model against the truth (body frame)"
"$bin/imucal" compare "$out/model.json" "$truth" --json "$out/compare.json"
echo "== free-inertial navigation of the navigation run with the calibrated model"
"$bin/imucal" navigate --db "$out/navigation.db" --model "$out/model.json" --out "$out/nav.csv" \
  --summary-json "$out/summary.json"
cat "$out/summary.json"
echo "results in $out/"
