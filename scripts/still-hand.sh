#!/usr/bin/env bash
# A still hand deep in tissue through the real processes: `sim-server run`
# on SCENE and `haptic-daemon run --device replay:` pressing a probe DEPTH_M
# below the top at (X, Y) and holding it; prints the rendered force over the
# last HOLD_WINDOW_S of the hold (mean, sd, min, max, zero ticks) from the
# daemon's record, and the simulation's own samples beside it.
#
#   scripts/still-hand.sh SCENE TOP_Z_M X_M Y_M DEPTH_M [daemon flags...]
#
# AXIS=y presses along -y instead (the embedded liver's tools come down
# along -y): then TOP is the surface's y and the other two are x and z.
#
# Needs the release binaries (cargo build --release -p sim-server -p haptic-daemon).
set -euo pipefail
scene=$1 top=$2 x=$3 y=$4 depth=$5
shift 5
here=$(cd "$(dirname "$0")/.." && pwd)
bin=$here/target/release
dir=$(mktemp -d)
session=still$$
python3 - "$dir/hand.csv" "$top" "$x" "$y" "$depth" "${AXIS:-z}" <<'PY'
import sys
out, top, a, b, depth = sys.argv[1], *map(float, sys.argv[2:6])
axis = sys.argv[6]
if axis not in ("y", "z"):
    sys.exit(f"AXIS={axis}: y or z")
rows = [(0, top + 0.003), (0.5, top + 0.003), (2.0, top - depth), (4.5, top - depth)]
at = (lambda h: (a, h, b)) if axis == "y" else (lambda h: (a, b, h))
open(out, "w").write("t_s,x_m,y_m,z_m\n" + "".join("{},{},{},{}\n".format(t, *at(h)) for t, h in rows))
PY
"$bin/sim-server" run --quiet --session "$session" --scene "$scene" --duration-s 30 --json "$dir/sim.json" &
sim=$!
sleep 2
"$bin/haptic-daemon" run --session "$session" --device "replay:$dir/hand.csv" --duration-s 4.5 \
  --record "$dir/rec.csv" --json "$dir/daemon.json" "$@" > "$dir/daemon.out"
kill -TERM $sim; wait $sim || true
python3 - "$dir" <<'PY'
import csv, json, math, sys
d = sys.argv[1]
rows = list(csv.DictReader(open(f"{d}/rec.csv")))
t0 = float(rows[0]["t_ns"]) if "t_ns" in rows[0] else 0.0
def force(r, k):
    return math.sqrt(sum(float(r[f"{k}_{a}_n"]) ** 2 for a in "xyz"))
key = "force" if "force_x_n" in rows[0] else None
if key is None:
    print("record columns:", list(rows[0].keys())); sys.exit(1)
ts = [(float(r["t_ns"]) - t0) * 1e-9 for r in rows]
window = [(t, force(r, "force"), r) for t, r in zip(ts, rows) if 3.5 <= t <= 4.4]
f = [w[1] for w in window]
n = len(f); mean = sum(f) / n
sd = math.sqrt(sum((x - mean) ** 2 for x in f) / n)
zeros = sum(1 for x in f if x < 1e-9)
print(f"rendered over {n} ticks (3.5-4.4 s): mean {mean:.4f} N, sd {sd:.4f} N ({100*sd/max(mean,1e-12):.2f}%), "
      f"min {min(f):.4f} N, max {max(f):.4f} N ({max(f)/max(mean,1e-12):.3f}x), zero ticks {zeros}")
s = json.load(open(f"{d}/sim.json"))
print("sim:", {k: s.get(k) for k in ("steps_per_s", "dropped_time_s", "stalls", "max_force_n", "nonlinear_tets", "contact_steps")}, "step_us", s.get("step_us"))
PY
echo "files in $dir"
