#!/usr/bin/env bash
# Fuzzes the mesh parsers (sim_server::mesh::io::parse_mesh): one cargo-fuzz
# target per format (msh, vtk, vtu, medit), each for SECONDS (default 60).
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#
# cargo-fuzz needs a nightly compiler (-Z sanitizer flags). A nightly
# toolchain is used if rustup has one; otherwise the stable compiler is run
# with RUSTC_BOOTSTRAP=1, which unlocks the same flags. The corpus starts
# from fuzz/seeds/<target> (small valid files, checked by the mesh_io tests)
# and grows in fuzz/corpus/<target>; crashes land in fuzz/artifacts/<target>.
# Exits non-zero if any target finds a crash, a leak, an OOM or a timeout.
set -euo pipefail

secs=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(msh vtk vtu medit)

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root/fuzz"

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "installing cargo-fuzz" >&2
    cargo install cargo-fuzz --locked
fi

if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then
    fuzz=(cargo +nightly fuzz)
else
    export RUSTC_BOOTSTRAP=1
    fuzz=(cargo fuzz)
fi

status=0
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t"
    cp -n seeds/"$t"/* "corpus/$t/" 2>/dev/null || true
    echo "== fuzzing $t for ${secs}s" >&2
    # -rss_limit_mb: a parser that allocates from a header count instead of
    # the input size fails here; -max_len keeps inputs near real file headers.
    if ! "${fuzz[@]}" run "$t" "corpus/$t" -- \
        -max_total_time="$secs" -rss_limit_mb=2048 -max_len=65536 -timeout=10 \
        -print_final_stats=1; then
        echo "!! $t: failure, see fuzz/artifacts/$t" >&2
        status=1
    fi
done
exit $status
