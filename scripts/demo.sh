#!/usr/bin/env bash
# Runs the whole stack on the embedded default scene with a simulated device,
# no hardware: sim-server run (the liver with its vessels, capsule and two
# tools) and haptic-daemon run (the real-time loop with a simulated hand that
# pokes the liver with tool 0, the grasper) in one session, for DURATION_S
# seconds (default 10), with both live status lines and both summaries.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cargo build --release --locked -p sim-server -p haptic-daemon
secs=${DURATION_S:-10}
session="demo$$"
./target/release/sim-server check
./target/release/sim-server run --session "$session" --duration-s "$((secs + 1))" &
sim=$!
trap 'kill $sim 2>/dev/null || true' EXIT
sleep 0.5
./target/release/haptic-daemon run --session "$session" --device simulated \
  --extrapolation local-model --duration-s "$secs"
wait $sim
