#!/usr/bin/env bash
# Measures the project's headline figures and writes docs/results/measured/:
# each benchmark's JSON (stamped with date, commit and machine) and the page
# `hapbench report` renders from it. Run on an idle machine; pages say which
# machine they came from. Usage: scripts/results.sh [OUT_DIR]
# (default docs/results/measured). Takes a few minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-docs/results/measured}"
mkdir -p "$out"
cargo build --release --locked --bins
bin=target/release
run() { echo "== $*" >&2; "$@" > /dev/null; }
# The explicit step on 8000 tetrahedra (one core, f32) and on the liver.
run "$bin/sim-server" bench --json "$out/core-step.json"
run "$bin/sim-server" bench --scene default --json "$out/liver-step.json"
# Extrapolators against the 1 kHz truth: the liver's press and slide at
# 60 Hz, and a 2.5 mm probe palpating a 5 mm-cell box at 30 Hz (issue 44's
# instrument narrower than the cells).
run "$bin/hapbench" extrapolation --json "$out/extrapolation-liver-60hz.json"
run "$bin/hapbench" extrapolation --scene tests/data/box-probe.toml \
  --trajectory tests/data/box-palpate.csv --sim-rate 30 \
  --json "$out/extrapolation-box-probe-30hz.json"
# Speed against accuracy for every backend, and the extremes.
run "$bin/hapbench" tradeoff --duration-s 0.3 --json "$out/tradeoff.json"
run "$bin/hapbench" stability --json "$out/stability.json"
# The real processes: latency and lateness beside bare baselines.
run "$bin/hapbench" latency --duration-s 3 --json "$out/latency.json"
"$bin/hapbench" report "$out"/*.json --out "$out"
