#!/usr/bin/env bash
# Runs the whole stack on the embedded default scene with a simulated device,
# no hardware: `sim-server demo` starts sim-server and haptic-daemon in one
# session; the daemon's simulated hand holds the grasper, which grips and
# pulls the left lobe while the cavitron removes right-lobe parenchyma; the
# viewer window opens when a display is available.
# DURATION_S seconds (default 10); live status lines, then a summary.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
cargo build --release --locked -p sim-server -p haptic-daemon
# The viewer window only where there is a display to open it on (its windowing
# dependencies take a minute to build); elsewhere the viewer does snapshots.
if [ -n "${DISPLAY:-}${WAYLAND_DISPLAY:-}" ]; then
  cargo build --release --locked -p viewer --features window
else
  cargo build --release --locked -p viewer
fi
exec ./target/release/sim-server demo --duration-s "${DURATION_S:-10}" "$@"
