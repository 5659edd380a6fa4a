#!/usr/bin/env bash
# Runs what exists of the stack on the embedded default scene, no hardware:
#  1. sim-server check: the embedded liver scene (mesh quality, materials,
#     vessels, capsule, stable step, enabled models);
#  2. sim-server bench --scene default: the liver simulated as fast as it goes;
#  3. haptic-daemon run: the hard-real-time loop with the simulated hand for
#     DURATION_S seconds (default 5), with its live status line and summary.
# `sim-server run` (tools, contact, the force stream to the daemon) and
# `sim-server demo` come next; until then the two processes run one after the other.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cargo build --release --locked -p sim-server -p haptic-daemon
echo "== the embedded scene"
./target/release/sim-server check
echo
echo "== the liver, stepped as fast as possible"
./target/release/sim-server bench --scene default --steps 2000
echo
echo "== the haptic loop (simulated hand), ${DURATION_S:-5} s"
./target/release/haptic-daemon run --device simulated --duration-s "${DURATION_S:-5}"
