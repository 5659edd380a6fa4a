#!/usr/bin/env bash
# Issue 44's slide acceptance on scenes and paths made here: a 2.5 mm probe
# over a 60 x 40 x 20 mm box of 5 mm cells (E 3 kPa, tests/data/box-probe-soft.toml)
# on three press-palpate-slide paths (written by this script at 1 kHz), each
# through `hapbench extrapolation --sim-rate 30`, on four models of the box:
# linear; linear refined to 2.5 mm under the paths ([[refine]]); the
# corotational region that follows the tip ([contact] corotational_radius_m
# = 0.012); both; the refinement that follows the tip ([contact]
# refine_radius_m = 0.008, cells of the probe's radius) with the linear
# model and with the region. Prints the truth's figures (p99 per-tick change,
# dropouts, the 2-vs-4 sub-step check) and each extrapolator's RMS error as
# a ratio to the constant hold's. Deterministic; about 14 minutes on 2 cores.
# Usage: scripts/slide-table.sh [OUT_DIR] (SCENES="region follow" to run some; NO_BUILD=1
# to use the hapbench already built)
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-$(mktemp -d)}"
mkdir -p "$out"
[ -n "${NO_BUILD:-}" ] || cargo build --release --locked -p hapbench
python3 - "$out" <<'PY'
import math, sys
out = sys.argv[1]
top, cx, cy = 0.02, 0.03, 0.02
def smooth(a):
    a = min(max(a, 0.0), 1.0)
    return a * a * (3 - 2 * a)
def path(depth, lateral, T, approach=0.5, retract=0.5):
    def f(t):
        if t < approach:
            d = -0.005 + smooth(t / approach) * (0.005 + depth(0)); x, y = lateral(0)
        elif t > T - retract:
            s = smooth((t - (T - retract)) / retract); t0 = T - retract - approach
            d = depth(t0) * (1 - s) - 0.005 * s; x, y = lateral(t0)
        else:
            d = depth(t - approach); x, y = lateral(t - approach)
        return x, y, top - d
    return f
def write(name, f, T=6.0):
    with open(f"{out}/{name}.csv", "w") as o:
        o.write("t_s,x_m,y_m,z_m\n")
        for k in range(int(T * 1000) + 1):
            x, y, z = f(k / 1000)
            o.write(f"{k / 1000:.3f},{x:.6f},{y:.6f},{z:.6f}\n")
# 8 +- 2 mm (palpated at 2 Hz for 1.5 s), then +-15 mm along x at 0.7 Hz.
write("p1-press-palpate-slide", path(
    lambda t: 0.008 + 0.002 * math.sin(2 * math.pi * 2 * t) * (t < 1.5),
    lambda t: (cx + (0.015 * math.sin(2 * math.pi * 0.7 * (t - 1.5)) if t > 1.5 else 0), cy), 6.0))
# 4-6 mm deep, a diagonal slide of +-12 x +-8 mm at 0.5 Hz.
write("p2-shallow-diagonal", path(
    lambda t: 0.005 + 0.001 * math.sin(2 * math.pi * 1.3 * t),
    lambda t: (cx + 0.012 * math.sin(2 * math.pi * 0.5 * t), cy + 0.008 * math.sin(2 * math.pi * 0.5 * t)), 6.0))
# 10 mm deep, a circle of 10 mm radius at 0.4 Hz.
write("p3-deep-circle", path(
    lambda t: 0.010,
    lambda t: (cx - 0.005 + 0.010 * math.cos(2 * math.pi * 0.4 * t), cy + 0.010 * math.sin(2 * math.pi * 0.4 * t)), 6.0))
PY
base=tests/data/box-probe-soft.toml
region=$'[contact]\ncorotational_radius_m = 0.012\n'
refine=$'[[refine]]\nselect = { box_m = [[0.01, 0.005, 0.008], [0.05, 0.035, 0.021]] }\ncell_m = 0.0025\n'
follow=$'refine_radius_m = 0.008\n'
cp "$base" "$out/linear.toml"
{ cat "$base"; echo; echo "$refine"; } > "$out/refined.toml"
{ cat "$base"; echo; echo "$region"; } > "$out/region.toml"
{ cat "$base"; echo; echo "$region"; echo "$refine"; } > "$out/region-refined.toml"
{ cat "$base"; echo; echo "[contact]"; echo "$follow"; } > "$out/follow.toml"
{ cat "$base"; echo; echo "$region"; echo "$follow"; } > "$out/region-follow.toml"
scenes="${SCENES:-linear refined region region-refined follow region-follow}"
for scene in $scenes; do
  for p in p1-press-palpate-slide p2-shallow-diagonal p3-deep-circle; do
    echo "== $scene $p" >&2
    target/release/hapbench extrapolation --scene "$out/$scene.toml" --trajectory "$out/$p.csv" \
      --sim-rate 30 --json "$out/$scene-$p.json" > /dev/null 2> "$out/$scene-$p.err"
  done
done
python3 - "$out" $scenes <<'PY'
import glob, json, os, sys
out = sys.argv[1]
print("| scene | path | truth max N | truth p99 change N | dropouts | sub-step check N | local-problem | away from snaps | local-model | net work LP mJ |")
print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for scene in sys.argv[2:]:
    for p in ["p1-press-palpate-slide", "p2-shallow-diagonal", "p3-deep-circle"]:
        v = json.load(open(f"{out}/{scene}-{p}.json")); m = v["methods"]
        c, ca = m["constant"]["rms_error_n"], m["constant"]["rms_error_away_from_snaps_n"]
        lp = m["local-problem"]
        print(f"| {scene} | {p} | {v['truth_max_force_n']:.3f} | {v['truth']['p99_jump_n']:.4f} | {v['truth_dropout_ticks']} | "
              f"{v['truth_check']['rms_difference_n']:.4f} | {lp['rms_error_n'] / c:.2f}x | {lp['rms_error_away_from_snaps_n'] / max(ca, 1e-12):.2f}x | "
              f"{m['local-model']['rms_error_n'] / c:.2f}x | {lp['net_energy_j'] * 1e3:.2f} |")
PY
