#!/usr/bin/env bash
# Peak resident memory of one distributed frame (feature mpi) against one
# process: `render` of each volume given, binary iso and RLE blend, in one
# process (/usr/bin/time %M) and on 1, 2 and 4 ranks (each rank's VmHWM from
# --json, with how its brick came: seek or scatter). Checks that the iso
# image at 4 ranks is the single process's. Keeps every JSON in $OUT.
# Usage: benches/scripts/distributed-memory.sh VOLUME...
#   BIN (default target/release/shearwarp, built with --features mpi),
#   RANKS (default "1 2 4"), OUT (default target/distributed-memory)
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-target/release/shearwarp}
OUT=${OUT:-target/distributed-memory}
RANKS=${RANKS:-1 2 4}
mkdir -p "$OUT"
MPIRUN=(mpirun --oversubscribe)
[[ $(id -u) -eq 0 ]] && MPIRUN+=(--allow-run-as-root)
for v in "$@"; do
    b=$(basename "$v")
    for mode in "--mode iso --method binary" "--mode blend --method rle"; do
        tag=$(echo "$mode" | awk '{print $2 "-" $4}')
        /usr/bin/time -f "%M" -o "$OUT/$b-$tag-one.rss" "$BIN" render "$v" $mode --sampling voxel --json -o "$OUT/$b-$tag-one.png" > "$OUT/$b-$tag-one.json"
        one=$(( $(cat "$OUT/$b-$tag-one.rss") * 1024 ))
        echo "$b $tag one process: peak $((one >> 20)) MiB"
        for n in $RANKS; do
            threads=$((n == 1 ? 2 : 1))
            "${MPIRUN[@]}" -np "$n" "$BIN" render "$v" $mode --threads $threads --distributed --json -o "$OUT/$b-$tag-$n.png" > "$OUT/$b-$tag-$n.json"
            echo "$b $tag $n ranks: $(jq -c --argjson one "$one" '[.per_rank[] | {rank, read, peak_mib: (.peak_rss_bytes / 1048576 | floor), of_one: (.peak_rss_bytes / $one * 100 | floor / 100)}]' "$OUT/$b-$tag-$n.json")"
        done
        if [[ $mode == *iso* ]]; then
            cmp "$OUT/$b-$tag-one.png" "$OUT/$b-$tag-${RANKS##* }.png" && echo "$b $tag: the image at ${RANKS##* } ranks is the single process's"
        fi
    done
done
