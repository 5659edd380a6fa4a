#!/usr/bin/env bash
# Issue 44's cost acceptance through the real processes: the embedded liver
# as shipped, and the same liver with the refinement that follows the tools
# ([contact] refine_radius_m = 0.015, refine_cell_m = 0.005) and multirate
# stepping ([simulation] multirate = true), run one after the other RUNS
# times (interleaved, so that both see the same machine). Each run is
# `sim-server run` beside `haptic-daemon run --device replay:` pressing and
# sliding the grasper (tests/data/press-slide.csv) for DURATION_S seconds.
# Prints, per run, the step the hand waits for (step_us p50 / p99 / p99.9),
# its CPU time (step_after_pose_cpu_us: the simulation's own part of a long
# step), its whole work, the dropped time and stalls, the steps predicted, the
# refinement's swaps, its largest mesh, the multirate partition, the first
# step on each swapped-in mesh and the tools' share of the step.
#
#   scripts/refined-liver-live.sh [RUNS] [DURATION_S]   (defaults 2 and 13)
#
# Needs the release binaries (cargo build --release -p sim-server -p haptic-daemon).
set -euo pipefail
runs=${1:-2}
secs=${2:-13}
here=$(cd "$(dirname "$0")/.." && pwd)
bin=$here/target/release
dir=$(mktemp -d)
cp "$here/sim-server/scenes/liver.toml" "$dir/plain.toml"
# The embedded scene ends in its [simulation] table: the first line lands there.
{ cat "$here/sim-server/scenes/liver.toml"; echo "multirate = true"; echo
  echo "[contact]"; echo "refine_radius_m = 0.015"; echo "refine_cell_m = 0.005"; } > "$dir/refined.toml"
one() { # SCENE LABEL
  local session=live$$$2 daemon_s
  daemon_s=$(python3 -c "print($secs - 3)")
  "$bin/sim-server" run --quiet --session "$session" --scene "$dir/$1.toml" --duration-s "$secs" \
    --json "$dir/$2.json" &
  local sim=$!
  sleep 2
  "$bin/haptic-daemon" run --quiet --rt-priority 0 --session "$session" \
    --device "replay:$here/tests/data/press-slide.csv" --duration-s "$daemon_s" > /dev/null
  wait $sim
}
for r in $(seq 1 "$runs"); do
  one plain "plain-$r"
  one refined "refined-$r"
done
python3 - "$dir" "$runs" <<'PY'
import json, sys
d, runs = sys.argv[1], int(sys.argv[2])
def p(s, k):
    v = s.get(k) or {}
    return f"{v.get('p50', 0):.0f} / {v.get('p99', 0):.0f} / {v.get('p999', 0):.0f}"
print("| run | step_us p50 / p99 / p99.9 | its CPU time p99 / p99.9 | step_work_us p50 / p99 / p99.9 | dropped (ms) / stalls | predicted | swaps | most tets | fast vertices | sub-steps coarse / fine | first step after a swap p50 / p99 (us) | contact_fraction |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for r in range(1, runs + 1):
    for label in ("plain", "refined"):
        s = json.load(open(f"{d}/{label}-{r}.json"))
        first = s.get("remesh_first_step_us") or {}
        cpu = s.get("step_after_pose_cpu_us") or {}
        print(f"| {label} {r} | {p(s, 'step_us')} | {cpu.get('p99', 0):.0f} / {cpu.get('p999', 0):.0f} | {p(s, 'step_work_us')} | "
              f"{s['dropped_time_s'] * 1e3:.0f} / {s['stalls']} | {s['predicted_steps']} of {s['steps']} | "
              f"{s.get('remesh_swaps', 0)} | {s.get('remesh_most_tets', 0)} | {s.get('multirate_fast_vertices', 0)} | "
              f"{s.get('multirate_coarse_substeps', 0)} / {s.get('multirate_fine_substeps', 0)} | "
              f"{first.get('p50', 0):.0f} / {first.get('p99', 0):.0f} | {s['contact_fraction']:.3f} |")
PY
