#!/usr/bin/env bash
# compare-rotators.sh -- the side-by-side rotation benchmark:
# VolPack (Lacroute's RLE shear-warp in C), VTK's vtkFixedPointVolumeRayCastMapper
# and `shearwarp rotate` (binary iso, RLE iso, RLE blend), the same volumes,
# views, image sizes and classifications, interleaved case by case in one run.
# Prints median ms per frame and the speed-ups against VolPack and VTK, then
# the limit of one shear step against a memcpy of the same bytes.
#
#   benches/scripts/compare-rotators.sh                   # everything, 360 frames per run
#   FRAMES=60 benches/scripts/compare-rotators.sh         # quicker
#   VOLUMES="brainsmall head256" SIZES=512 benches/scripts/compare-rotators.sh
#
# Environment:
#   FRAMES=360      frames per run (1° steps about the volume's y axis)
#   ROUNDS=1        repeat every case; the table takes the median of the runs
#   VOLUMES="brainsmall brainsmall-up2 head256 chest"   which volumes (also chest413:
#                   the chest CT resampled to 512×512×413, about 5 minutes more)
#   SIZES="256 512" output sizes
#   NO_VTK=1        skip VTK (its runs dominate the wall time)
#   NO_SHEAR_BENCH=1  skip the criterion shear-step-vs-memcpy bench at the end
#   OUT=dir         build and output directory (default target/compare)
#
# Installs libvolpack1-dev (apt-get), the vtk wheel (pip) and, only if VTK
# cannot render off screen, xvfb; builds target/release/shearwarp and the
# VolPack harness. How the classifications and views are matched:
# benches/scripts/volpack/README.md, benches/scripts/vtk/README.md and README.md
# ("Side by side with VolPack and VTK").
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
OUT=${OUT:-$ROOT/target/compare}
FRAMES=${FRAMES:-360}
ROUNDS=${ROUNDS:-1}
VOLUMES=${VOLUMES:-brainsmall brainsmall-up2 head256 chest}
SIZES=${SIZES:-256 512}
SW=$ROOT/target/release/shearwarp
VP=$OUT/volpack-harness
VTK_PY=$ROOT/benches/scripts/vtk/harness.py
NCPU=$(nproc)

# shellcheck source=volpack/setup.sh
. "$ROOT/benches/scripts/volpack/setup.sh"

# ---------------------------------------------------------------- install and build
mkdir -p "$OUT/data" "$OUT/runs" "$OUT/frames"
volpack_harness "$VP"
(cd "$ROOT" && cargo build --release --quiet)

VTK_RUN=()
if [ -z "${NO_VTK:-}" ]; then
    if ! python3 -c 'import vtk' 2>/dev/null; then
        log "installing the vtk wheel"
        python3 -m pip install --quiet vtk >&2 || apt_install python3-vtk9
    fi
    # off screen first; a virtual X server only if that cannot render
    "$SW" export --phantom sphere --phantom-dims 16,16,16 -o "$OUT/data/probe.den" >/dev/null
    if python3 "$VTK_PY" --den "$OUT/data/probe.den" --frames 1 --size 32 >/dev/null 2>"$OUT/data/probe.log"; then
        VTK_RUN=(python3 "$VTK_PY")
    else
        command -v xvfb-run >/dev/null 2>&1 || apt_install xvfb xauth
        VTK_RUN=(xvfb-run -a -s "-screen 0 1280x1024x24" python3 "$VTK_PY")
        "${VTK_RUN[@]}" --den "$OUT/data/probe.den" --frames 1 --size 32 >/dev/null ||
            { log "VTK cannot render here (see $OUT/data/probe.log); set NO_VTK=1"; exit 1; }
    fi
fi

# ---------------------------------------------------------------- volumes (all u8 .den, read by all three)
# name -> file, and the opaque threshold T in the file's 8-bit units:
# VolPack's opaque classification is alpha = clamp((d - T)/4, 0, 1).
declare -A DEN THR
BRAINSMALL=$(find_brainsmall) || BRAINSMALL=""
CHEST=""
for c in "$ROOT/../shared/data/chest-ct-lung1.nrrd" /work/shared/data/chest-ct-lung1.nrrd; do
    [ -f "$c" ] && { CHEST=$(realpath "$c"); break; }
done
for v in $VOLUMES; do
    case $v in
    brainsmall)
        [ -n "$BRAINSMALL" ] || { log "brainsmall.den not found"; exit 1; }
        DEN[$v]=$BRAINSMALL; THR[$v]=24 ;;
    brainsmall-up2)
        DEN[$v]=$OUT/data/brainsmall-up2.den; THR[$v]=24
        [ -f "${DEN[$v]}" ] || "$VP" --den "$BRAINSMALL" --upsample 2 --write-den "${DEN[$v]}" --frames 0 >/dev/null ;;
    head256)
        # the head phantom in HU, 10 HU per step: d = (HU + 1000)/10, skin (-500 HU) at 50
        DEN[$v]=$OUT/data/head256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$SW" export --phantom head --phantom-dims 256,256,256 --window -1000,1550 -o "${DEN[$v]}" >&2 ;;
    chest)
        # LIDC chest CT 512x512x48 at 0.57x0.57x5 mm: cubic 1.14 mm voxels (VolPack has no spacing)
        [ -n "$CHEST" ] || { log "chest-ct-lung1.nrrd not found (skip it: VOLUMES=...)"; exit 1; }
        DEN[$v]=$OUT/data/chest256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$SW" export "$CHEST" --window -1000,1550 --max-dim 256 -o "${DEN[$v]}" >&2 ;;
    chest413)
        # the same CT resampled along z to 413 slices (0.57 mm: a thin-slice
        # 512x512x413 stand-in, benches/scripts/resample-nrrd.py), full size
        [ -n "$CHEST" ] || { log "chest-ct-lung1.nrrd not found (skip it: VOLUMES=...)"; exit 1; }
        DEN[$v]=$OUT/data/chest413.den; THR[$v]=50
        if [ ! -f "${DEN[$v]}" ]; then
            python3 "$ROOT/benches/scripts/resample-nrrd.py" "$CHEST" "$OUT/data/chest413.nrrd" 413 >&2
            "$SW" export "$OUT/data/chest413.nrrd" --window -1000,1550 -o "${DEN[$v]}" >&2
            rm -f "$OUT/data/chest413.nrrd"
        fi ;;
    *) log "unknown volume $v"; exit 1 ;;
    esac
done

# ---------------------------------------------------------------- runners (each prints a median ms/frame)
json_num() { tr -d '\n' | sed -n "s/.*\"$1\"[[:space:]]*:[[:space:]]*\([-0-9.eE+]*\).*/\1/p"; }
median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END { if (NR == 0) print "";
    else if (NR % 2) print a[(NR+1)/2]; else printf "%.4f\n", (a[NR/2] + a[NR/2+1]) / 2 }'; }
speedup() { awk -v a="$1" -v b="$2" 'BEGIN { if (a == "" || b == "" || b == 0) print "-"; else printf "%.2f×", a / b }'; }
fmt() { awk -v a="$1" 'BEGIN { if (a == "") print "-"; else printf "%.2f", a }'; }

volpack() { # volpack DEN SIZE TF T
    local j
    j=$("$VP" --den "$1" --size "$2" --tf "$3" --threshold "$4" --frames "$FRAMES" --step-deg 1) || return 0
    printf '%s\n' "$j" >>"$OUT/runs/volpack.jsonl"; printf '%s' "$j" | json_num frame_ms_median
}
vtk() { # vtk DEN SIZE T THREADS
    local j
    j=$("${VTK_RUN[@]}" --den "$1" --size "$2" --tf opaque --threshold "$3" --threads "$4" \
        --frames "$FRAMES" --step-deg 1) || return 0
    printf '%s\n' "$j" >>"$OUT/runs/vtk.jsonl"; printf '%s' "$j" | json_num frame_ms_median
}
ours() { # ours DEN SIZE THREADS ARGS...  (--view superior: eye y = volume y, VolPack's rotation axis)
    local den=$1 size=$2 thr=$3 j; shift 3
    j=$("$SW" rotate --den "$den" --view superior --axis y --degrees "$FRAMES" --step-deg 1 \
        --size "$size" --threads "$thr" --quiet --json "$@") || return 0
    printf '%s\n' "$j" >>"$OUT/runs/ours.jsonl"; printf '%s' "$j" | json_num frame_ms_median
}

# ---------------------------------------------------------------- run, interleaved case by case
: >"$OUT/runs/volpack.jsonl"; : >"$OUT/runs/vtk.jsonl"; : >"$OUT/runs/ours.jsonl"
ISO_ROWS=(); BLEND_ROWS=()
for v in $VOLUMES; do
    den=${DEN[$v]}; t=${THR[$v]}
    iso=$((t + 2))  # VolPack's opaque ramp reaches opacity 0.5 at T + 2
    # VolPack's ramp 0.3·(d−T)/(255−T) with its 0.05 voxel cut, as an opacity curve
    cut=$(awk -v t="$t" 'BEGIN { printf "%.3f", t + (255 - t) * 0.05 / 0.3 }')
    ramp="$cut:0,$cut:0.05,255:0.3"
    dims=$("$SW" info "$den" --json | sed -n 's/.*"dims":\[\([0-9]*\),\([0-9]*\),\([0-9]*\)\].*/\1×\2×\3/p')
    for size in $SIZES; do
        log "== $v $dims at ${size}², $FRAMES frames, $ROUNDS round(s)"
        declare -A R=()
        for ((r = 0; r < ROUNDS; r++)); do
            R[vp_op]+=" $(volpack "$den" "$size" opaque "$t")"
            R[bin1]+=" $(ours "$den" "$size" 1 --method binary --iso "$iso")"
            R[binN]+=" $(ours "$den" "$size" 0 --method binary --iso "$iso")"
            R[rle1]+=" $(ours "$den" "$size" 1 --method rle --iso "$iso" --ert 0.95)"
            R[rleN]+=" $(ours "$den" "$size" 0 --method rle --iso "$iso" --ert 0.95)"
            if [ ${#VTK_RUN[@]} -gt 0 ]; then
                R[vtk1]+=" $(vtk "$den" "$size" "$t" 1)"
                R[vtkN]+=" $(vtk "$den" "$size" "$t" "$NCPU")"
            fi
            R[vp_ramp]+=" $(volpack "$den" "$size" ramp "$t")"
            R[blend1]+=" $(ours "$den" "$size" 1 --method rle --mode blend --opacity "$ramp" --ert 0.95)"
            R[blendN]+=" $(ours "$den" "$size" 0 --method rle --mode blend --opacity "$ramp" --ert 0.95)"
        done
        declare -A M=()
        for k in "${!R[@]}"; do
            # shellcheck disable=SC2086  # a space-separated list of numbers
            M[$k]=$(median ${R[$k]})
        done
        ISO_ROWS+=("| $v | $dims | ${size}² | $(fmt "${M[vp_op]}") | $(fmt "${M[vtk1]:-}") | $(fmt "${M[vtkN]:-}") | $(fmt "${M[bin1]}") | $(fmt "${M[binN]}") | $(fmt "${M[rle1]}") | $(fmt "${M[rleN]}") | $(speedup "${M[vp_op]}" "${M[bin1]}") | $(speedup "${M[vp_op]}" "${M[binN]}") | $(speedup "${M[vtkN]:-}" "${M[binN]}") | $(speedup "${M[vtk1]:-}" "${M[bin1]}") |")
        BLEND_ROWS+=("| $v | $dims | ${size}² | $(fmt "${M[vp_ramp]}") | $(fmt "${M[blend1]}") | $(fmt "${M[blendN]}") | $(speedup "${M[vp_ramp]}" "${M[blend1]}") | $(speedup "${M[vp_ramp]}" "${M[blendN]}") |")
        unset R M
    done
done

echo
echo "Median ms per frame, $FRAMES frames in 1° steps about the volume's y axis, one run per cell"
echo "(ROUNDS=$ROUNDS), $(uname -m), $NCPU cores, $(date -u +%Y-%m-%dT%H:%MZ). VolPack is single-threaded;"
echo "'all' = $NCPU threads. Speed-ups are other/ours: > 1 means shearwarp is faster."
echo
echo "Iso / opaque: VolPack alpha = clamp((d−T)/4, 0, 1); VTK the same opacity curve; shearwarp --iso T+2."
echo
echo "| volume | dims | image | VolPack | VTK 1 | VTK all | binary 1 | binary all | rle 1 | rle all | binary 1 vs VolPack | binary all vs VolPack | binary all vs VTK all | binary 1 vs VTK 1 |"
echo "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
printf '%s\n' "${ISO_ROWS[@]}"
echo
echo "Blend: VolPack ramp alpha = 0.3·clamp((d−T)/(255−T), 0, 1), voxels with alpha ≤ 0.05 dropped,"
echo "ray termination at 0.95; shearwarp --method rle --mode blend with the same curve and --ert 0.95."
echo
echo "| volume | dims | image | VolPack ramp | rle blend 1 | rle blend all | rle 1 vs VolPack | rle all vs VolPack |"
echo "|---|---|---|---:|---:|---:|---:|---:|"
printf '%s\n' "${BLEND_ROWS[@]}"
echo
echo "raw JSON lines: $OUT/runs/"

# ---------------------------------------------------------------- the limit of a shear step
if [ -z "${NO_SHEAR_BENCH:-}" ]; then
    echo
    echo "One shear step of the 256×256×225 head mask against a memcpy of the bytes it touches (criterion, one thread, same run):"
    (cd "$ROOT" && cargo bench --quiet --bench skips -- shear_step_vs_memcpy 2>/dev/null) |
        grep -E '^shear_step_vs_memcpy|time:' | paste - - | sed 's/  */ /g'
fi
