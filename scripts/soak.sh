#!/usr/bin/env bash
# The long soak (not in CI): sim-server, haptic-daemon and the recorder for
# SOAK_S seconds (default 600); fails on any lost force sample or tick or on
# memory growth. CI runs the same test for 20 s.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
HAPSIM_SOAK_S="${SOAK_S:-600}" cargo test --release --locked -p system-tests --test soak -- --nocapture
