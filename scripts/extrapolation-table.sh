#!/usr/bin/env bash
# The twelve `hapbench extrapolation` runs (box press-palpate-slide,
# box stroke, the embedded liver's press-slide; simulation at 30, 60, 100 and
# 250 Hz, haptic loop at 1 kHz), printed as its Markdown table: each method's
# RMS error (N) with its ratio to the constant hold, p99 per-tick change (N)
# and net work on the hand (mJ; positive = energy injected), then each
# method's mean and largest ratio over the twelve. DELAY_MS adds a transport
# delay to every sample and problem (`--delay-ms`). Offline and
# deterministic: the errors do not depend on the machine; the render times
# in the JSON do.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked -p hapbench >/dev/null
out=${OUT:-target/extrapolation-table}
delay=${DELAY_MS:-0}
mkdir -p "$out"
paths=(
  "box-palpate|--scene tests/data/box-probe.toml --trajectory tests/data/box-palpate.csv"
  "box-stroke|--scene tests/data/box-probe.toml --trajectory tests/data/box-stroke.csv"
  "liver|"
)
rates=(30 60 100 250)
for p in "${paths[@]}"; do
  name=${p%%|*}
  # shellcheck disable=SC2206 # the flags split on purpose
  flags=(${p#*|})
  for r in "${rates[@]}"; do
    ./target/release/hapbench extrapolation "${flags[@]}" --sim-rate "$r" --delay-ms "$delay" \
      --json "$out/$name-$r.json" >/dev/null
  done
done
echo "machine: $(lscpu | sed -n 's/^Model name: *//p' | head -1), $(nproc) cores, $(date -u +%Y-%m-%d), delay ${delay} ms"
echo
python3 - "$out" <<'PY'
import json, sys
out = sys.argv[1]
paths = [("box-palpate", "box, press-palpate-slide"), ("box-stroke", "box, stroke"),
         ("liver", "liver, press-slide")]
rates = [30, 60, 100, 250]
first = json.load(open(f"{out}/box-palpate-30.json"))["methods"]
methods = ["constant"] + sorted(m for m in first if m != "constant")
print("| path | sim Hz | " + " | ".join(methods) + " |")
print("|---|---|" + "---|" * len(methods))
ratios = {m: [] for m in methods}
for name, label in paths:
    for r in rates:
        m = json.load(open(f"{out}/{name}-{r}.json"))["methods"]
        c = m["constant"]["rms_error_n"]
        cells = []
        for k in methods:
            x = m[k]
            ratios[k].append(x["rms_error_n"] / c)
            cells.append(f"{x['rms_error_n']:.4f} ({x['rms_error_n'] / c:.2f}), "
                         f"{x['p99_jump_n']:.3f}, {x['net_energy_j'] * 1e3:.2f}")
        print(f"| {label} | {r} | " + " | ".join(cells) + " |")
print()
for k in methods:
    v = ratios[k]
    print(f"{k}: {sum(v) / len(v):.3f}x the constant hold on average, at most {max(v):.3f}x")
PY
