#!/usr/bin/env bash
# ab-binaries.sh OLD NEW -- interleaved A/B of two shearwarp binaries on the
# volumes of compare-rotators.sh, at one image size, 1 and 2 threads: binary iso,
# RLE iso and RLE blend (VolPack's classifications, as compare-rotators.sh
# matches them). Every round runs OLD then NEW (then NEW then OLD in the next
# round, so neither always runs second) for every case; the table gives the
# median frame ms of each and the ratio NEW/OLD of the medians.
#
#   benches/scripts/ab-binaries.sh /path/to/old/shearwarp target/release/shearwarp
#   ROUNDS=7 FRAMES=120 SIZE=512 VOLUMES="brainsmall head256" benches/scripts/ab-binaries.sh OLD NEW
#   CASES=binary-iso VOLUMES="chest chest512" benches/scripts/ab-binaries.sh OLD NEW
#
# The volumes are .den files written by NEW's `export` into OUT (default
# target/ab): brainsmall (from $SHEARWARP_DATA or ../shared/data), brainsmall
# resampled to 256×256×168, the head phantom at 256³ and the chest CT at
# 256×256×207 (and, when asked for, at 512×512×413: chest512). CASES picks
# among binary-iso, rle-iso and rle-blend (default: all three).
set -euo pipefail
OLD=$(realpath "$1")
NEW=$(realpath "$2")
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
OUT=${OUT:-$ROOT/target/ab}
ROUNDS=${ROUNDS:-5}
FRAMES=${FRAMES:-90}
SIZE=${SIZE:-512}
THREADS=${THREADS:-1 2}
VOLUMES=${VOLUMES:-brainsmall brainsmall-up2 head256 chest}
CASES=${CASES:-binary-iso rle-iso rle-blend}
DATA=${SHEARWARP_DATA:-$ROOT/../shared/data}
mkdir -p "$OUT"

declare -A DEN THR
for v in $VOLUMES; do
    case $v in
    brainsmall) DEN[$v]=$DATA/brainsmall.den; THR[$v]=24 ;;
    brainsmall-up2)
        DEN[$v]=$OUT/brainsmall-up2.den; THR[$v]=24
        [ -f "${DEN[$v]}" ] || "$NEW" export "$DATA/brainsmall.den" --window 0,255 --max-dim 256 -o "${DEN[$v]}" >&2 ;;
    head256)
        DEN[$v]=$OUT/head256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$NEW" export --phantom head --phantom-dims 256,256,256 --window -1000,1550 -o "${DEN[$v]}" >&2 ;;
    chest)
        DEN[$v]=$OUT/chest256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$NEW" export "$DATA/chest-ct-lung1.nrrd" --window -1000,1550 --max-dim 256 -o "${DEN[$v]}" >&2 ;;
    chest512)
        DEN[$v]=$OUT/chest512.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$NEW" export "$DATA/chest-ct-lung1.nrrd" --window -1000,1550 --max-dim 512 -o "${DEN[$v]}" >&2 ;;
    *) echo "unknown volume $v" >&2; exit 1 ;;
    esac
done

json_num() { tr -d '\n' | sed -n "s/.*\"$1\"[[:space:]]*:[[:space:]]*\([-0-9.eE+]*\).*/\1/p"; }
median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END { if (NR % 2) print a[(NR+1)/2]; else printf "%.4f\n", (a[NR/2] + a[NR/2+1]) / 2 }'; }
run() { # run BIN DEN THREADS ARGS...
    local bin=$1 den=$2 thr=$3; shift 3
    "$bin" rotate --den "$den" --view superior --axis y --degrees "$FRAMES" --step-deg 1 \
        --size "$SIZE" --threads "$thr" --quiet --json "$@" | json_num frame_ms_median
}

printf '| volume | case | threads | old ms | new ms | new/old |\n|---|---|---:|---:|---:|---:|\n'
for v in $VOLUMES; do
    den=${DEN[$v]}; t=${THR[$v]}
    cut=$(awk -v t="$t" 'BEGIN { printf "%.3f", t + (255 - t) * 0.05 / 0.3 }')
    for c in $CASES; do
        case $c in
        binary-iso) args=(--method binary --iso $((t + 2))) ;;
        rle-iso) args=(--method rle --iso $((t + 2))) ;;
        rle-blend) args=(--method rle --mode blend --opacity "$cut:0,$cut:0.05,255:0.3" --ert 0.95) ;;
        esac
        for thr in $THREADS; do
            a=(); b=()
            for r in $(seq "$ROUNDS"); do
                if [ $((r % 2)) -eq 1 ]; then
                    a+=("$(run "$OLD" "$den" "$thr" "${args[@]}")"); b+=("$(run "$NEW" "$den" "$thr" "${args[@]}")")
                else
                    b+=("$(run "$NEW" "$den" "$thr" "${args[@]}")"); a+=("$(run "$OLD" "$den" "$thr" "${args[@]}")")
                fi
            done
            ma=$(median "${a[@]}"); mb=$(median "${b[@]}")
            printf '| %s | %s | %s | %.3f | %.3f | %s |\n' "$v" "$c" "$thr" "$ma" "$mb" \
                "$(awk -v a="$ma" -v b="$mb" 'BEGIN { printf "%.3f", b / a }')"
        done
    done
done
