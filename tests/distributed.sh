#!/usr/bin/env bash
# The distributed (MPI) build and its tests: installs Open MPI and libclang
# with apt-get when missing (as root; fails loudly when it cannot), builds with
# the feature `mpi`, runs the distributed tests of the test crate (1–4 ranks,
# oversubscribed) and a smoke test of `render` and `rotate --distributed` at
# 2 and 4 ranks against the single process (`cmp` of the iso images) and of
# `bench --distributed`.
# Usage: tests/distributed.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=target/distributed-test

have_tools() {
    command -v mpirun >/dev/null 2>&1 && command -v mpicc >/dev/null 2>&1 &&
        { ls /usr/lib/llvm-*/lib/libclang*.so* >/dev/null 2>&1 || ls /usr/lib/*/libclang*.so* >/dev/null 2>&1; }
}
if ! have_tools; then
    echo "test-distributed: installing libopenmpi-dev openmpi-bin libclang-dev"
    if [[ $(id -u) -ne 0 ]] || ! command -v apt-get >/dev/null; then
        echo "test-distributed: FAIL: Open MPI (mpirun, mpicc) or libclang is missing and cannot be installed here (need root and apt-get)" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    if ! { apt-get update -qq && apt-get install -y -qq libopenmpi-dev openmpi-bin libclang-dev >/dev/null; }; then
        echo "test-distributed: FAIL: apt-get could not install Open MPI and libclang" >&2
        exit 1
    fi
fi

MPIRUN=(mpirun --oversubscribe)
[[ $(id -u) -eq 0 ]] && MPIRUN+=(--allow-run-as-root)

cargo clippy --release --all-targets --features mpi -- -D warnings
cargo build --release --features mpi
cargo test --release --features mpi --test it -- distributed:: bricks::

mkdir -p "$OUT"
BIN=target/release/shearwarp
"$BIN" render --sampling voxel --tissue bone --rotate 15,40,0 -o "$OUT/one.png"
for n in 2 4; do
    timeout 300 "${MPIRUN[@]}" -np "$n" "$BIN" render --distributed --tissue bone --rotate 15,40,0 -o "$OUT/d$n.png" --json > "$OUT/d$n.json"
    cmp "$OUT/one.png" "$OUT/d$n.png"
    timeout 300 "${MPIRUN[@]}" -np "$n" "$BIN" rotate --distributed --degrees 30 --cell 2 --cycle-tissues 5
    timeout 300 "${MPIRUN[@]}" -np "$n" "$BIN" bench --distributed --only binary-c1-u64-bitscan,rle \
        --size 128 --reps 1 --rounds 1 --random-views 0 --quiet --json-out "$OUT/bench$n.json" > "$OUT/bench$n.md"
    grep -q '| blend | rle |' "$OUT/bench$n.md"
done
echo "test-distributed: ok (render at 2 and 4 ranks equal to one process; rotate and bench ran)"
