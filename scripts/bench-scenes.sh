#!/usr/bin/env bash
# What the liver scene's extra models cost per step: the isotropic-only liver,
# the full embedded liver (vessels, linear capsule), and the same with the
# nonlinear capsule (paper eq 29 every step). Same mesh, same dt (under every
# variant's bound, so one sub-step), one thread. Runs each ROUNDS times
# (default 5), interleaved, and prints the medians in a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked -p sim-server >/dev/null
rounds=${ROUNDS:-5}
out=${OUT:-target/bench-scenes}
mkdir -p "$out"
declare -A scenes=(
  [isotropic]=sim-server/scenes/bench/liver-isotropic.toml
  [full-linear-capsule]=default
  [full-nonlinear-capsule]=sim-server/scenes/bench/liver-nonlinear-membrane.toml
)
order=(isotropic full-linear-capsule full-nonlinear-capsule)
for r in $(seq "$rounds"); do
  for name in "${order[@]}"; do
    ./target/release/sim-server bench --scene "${scenes[$name]}" --dt-s 3e-4 --steps 10000 \
      --json "$out/$name-$r.json" >/dev/null
  done
done
echo "machine: $(lscpu | sed -n 's/^Model name: *//p' | head -1), $(nproc) cores, $(date -u +%Y-%m-%d), $rounds rounds"
echo
python3 - "$out" "$rounds" "${order[@]}" <<'PY'
import json, statistics, sys
out, rounds, names = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
med = {}
for n in names:
    us = [json.load(open(f"{out}/{n}-{r}.json"))["ns_per_step"] / 1e3 for r in range(1, rounds + 1)]
    med[n] = statistics.median(us)
base = med[names[0]]
print("| scene | tets | us/step (median) | relative to isotropic |")
print("|---|---:|---:|---:|")
for n in names:
    tets = json.load(open(f"{out}/{n}-1.json"))["tets"]
    print(f"| {n} | {tets} | {med[n]:.1f} | {med[n] / base:.2f} |")
PY
