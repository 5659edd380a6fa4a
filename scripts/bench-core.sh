#!/usr/bin/env bash
# Step rate of the tensor-mass core against mesh size (1k to 1M tetrahedra),
# one thread and all threads, beside the bandwidth probe of the same run.
# Prints a Markdown table, one row per size and thread count from RUNS
# (default 3) runs; JSON files go to ${OUT:-target/bench-core}.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked -p sim-server >/dev/null
out=${OUT:-target/bench-core}
mkdir -p "$out"
threads_all=$(nproc)
echo "machine: $(lscpu | sed -n 's/^Model name: *//p' | head -1), $(nproc) cores, $(date -u +%Y-%m-%d)"
echo
runs=${RUNS:-3}
echo "| tets | threads | steps/s | us/step | MB/step | probe GB/s | bandwidth bound steps/s | fraction of bound | fraction, each run |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---|"
for tets in 1000 8000 100000 1000000; do
  steps=$(( 40000000 / tets )); [ "$steps" -lt 60 ] && steps=60; [ "$steps" -gt 20000 ] && steps=20000
  for t in 1 "$threads_all"; do
    # Several runs per row (the machine is shared): the row is the run with
    # the median step rate, the last column every run's fraction.
    files=()
    for r in $(seq "$runs"); do
      f="$out/box-$tets-t$t-r$r.json"
      ./target/release/sim-server bench --generate box --tets "$tets" --steps "$steps" --threads "$t" --json "$f" >/dev/null
      files+=("$f")
    done
    python3 - "${files[@]}" <<'PY'
import json, sys
runs = [json.load(open(f)) for f in sys.argv[1:]]
r = sorted(runs, key=lambda x: x['steps_per_s'])[len(runs) // 2]
each = ", ".join(f"{x['fraction_of_bandwidth_bound']:.2f}" for x in runs)
print(f"| {r['tets']} | {r['threads']} | {r['steps_per_s']:.0f} | {r['ns_per_step']/1e3:.1f} | {r['bytes_per_step']/1e6:.2f} | {r['bandwidth_bytes_per_s']/1e9:.1f} | {r['bandwidth_bound_steps_per_s']:.0f} | {r['fraction_of_bandwidth_bound']:.2f} | {each} |")
PY
  done
done
