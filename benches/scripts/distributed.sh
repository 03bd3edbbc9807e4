#!/usr/bin/env bash
# The distributed frame (feature mpi) against one process: frame time, bytes
# per frame and peak memory per rank at 1, 2 and 4 ranks, for each volume
# given (default: the head phantom exported as 8-bit .den at 256³ and 512³
# into $OUT). Prints one line per run and keeps every JSON in $OUT.
# Usage: benches/scripts/distributed.sh [VOLUME.den ...]
#   BIN (default target/release/shearwarp, built with --features mpi),
#   RANKS (default "1 2 4"), DEGREES (default 30), OUT (default target/distributed-bench)
set -euo pipefail
cd "$(dirname "$0")/../.."
BIN=${BIN:-target/release/shearwarp}
OUT=${OUT:-target/distributed-bench}
RANKS=${RANKS:-1 2 4}
DEGREES=${DEGREES:-30}
mkdir -p "$OUT"
vols=("$@")
if [[ ${#vols[@]} -eq 0 ]]; then
    for n in 256 512; do
        [[ -f $OUT/head$n.den ]] || "$BIN" export --phantom head --phantom-dims $n,$n,$n -o "$OUT/head$n.den" 2>/dev/null
        vols+=("$OUT/head$n.den")
    done
fi
MPIRUN=(mpirun --oversubscribe)
[[ $(id -u) -eq 0 ]] && MPIRUN+=(--allow-run-as-root)
for v in "${vols[@]}"; do
    b=$(basename "$v" .den)
    for mode in "--method binary --mode iso" "--method rle --mode blend"; do
        tag=$(echo "$mode" | awk '{print $2 "-" $4}')
        # one process, for its peak memory (kB) and frame time
        /usr/bin/time -f "%M" -o "$OUT/$b-$tag-one.rss" "$BIN" rotate "$v" $mode --degrees "$DEGREES" --json > "$OUT/$b-$tag-one.json"
        echo "$b $tag one process: peak $(cat "$OUT/$b-$tag-one.rss") kB, $(jq -c '{frames, frame_ms_median, shear_ms_median, render_ms_median, warp_ms_median}' "$OUT/$b-$tag-one.json")"
        for n in $RANKS; do
            # the host's 2 cores shared: 2 threads for one rank, 1 each for more
            threads=$((n == 1 ? 2 : 1))
            "${MPIRUN[@]}" -np "$n" "$BIN" rotate "$v" $mode --degrees "$DEGREES" --threads $threads --distributed --json > "$OUT/$b-$tag-$n.json"
            echo "$b $tag $n ranks: $(jq -c '{frames, frame_ms_median, per_rank: [.per_rank[] | {rank, render_ms, gather_ms, composite_ms, sent: .sent_bytes_per_frame, received: .received_bytes_per_frame, peak_mb: (.peak_rss_bytes / 1048576 | floor)}]}' "$OUT/$b-$tag-$n.json")"
        done
    done
done
