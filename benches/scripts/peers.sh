#!/usr/bin/env bash
# peers.sh -- the peer charts: every shearwarp method beside VolPack and VTK,
# frame time against error, the peers' frames measured by shearwarp's own
# reference with the peers' model (`shearwarp bench --peers`), one run per
# volume, image size and thread count.
#
#   benches/scripts/peers.sh                         # everything (tens of minutes)
#   VOLUMES=brainsmall SIZES=512 THREADS=2 benches/scripts/peers.sh
#
# Environment:
#   VOLUMES="brainsmall head256 chest mri"   which volumes (mri: head-mri-ch2.nii.gz)
#   SIZES="256 512"      output sizes
#   THREADS="1 N"        thread counts (N = all cores)
#   ONLY=...             --only list for shearwarp's rows (default: every variant)
#   DELUXE="S I"         Deluxe option sets every row is measured under, in one run
#                        (default: none given, the matrix's own parallel Deluxe rows)
#   PERSPECTIVE=40       a perspective field of view measured too ("" for none)
#   ROUNDS=1 REPS=3 RANDOM_VIEWS=2 REF_STEP=0.1
#   OUT=dir              output directory (default target/peers)
#
# Installs libvolpack1-dev (apt-get) and the vtk wheel (pip) when missing,
# builds target/release/shearwarp. Writes per run OUT/<volume>-<size>-t<threads>
# .md (the tables, the model floor, the matched/not-matched line of every peer),
# .json (records and summary: peers are rows whose variant names the peer),
# .csv and .svg (time against RMSE, Pareto front marked).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
OUT=${OUT:-$ROOT/target/peers}
VOLUMES=${VOLUMES:-brainsmall head256 chest mri}
SIZES=${SIZES:-256 512}
NCPU=$(nproc)
THREADS=${THREADS:-1 $NCPU}
PERSPECTIVE=${PERSPECTIVE-40}
ROUNDS=${ROUNDS:-1}
REPS=${REPS:-3}
RANDOM_VIEWS=${RANDOM_VIEWS:-2}
REF_STEP=${REF_STEP:-0.1}
SW=$ROOT/target/release/shearwarp

# shellcheck source=volpack/setup.sh
. "$ROOT/benches/scripts/volpack/setup.sh"

mkdir -p "$OUT/data"
volpack_harness "$ROOT/target/volpack/harness"
if ! python3 -c 'import vtk' 2>/dev/null; then
    log "installing the vtk wheel"
    python3 -m pip install --quiet vtk numpy >&2 || apt_install python3-vtk9
fi
(cd "$ROOT" && cargo build --release --quiet)

data() { # the first existing copy of a shared data file
    local c
    for c in "$ROOT/../shared/data/$1" /work/shared/data/"$1"; do
        [ -e "$c" ] && { realpath "$c"; return 0; }
    done
    log "$1 not found (set VOLUMES to skip it)"; exit 1
}

# name -> .den file and the opaque threshold in its 8-bit units ("" = the bench's tissue default)
declare -A DEN THR
for v in $VOLUMES; do
    case $v in
    brainsmall) DEN[$v]=$(find_brainsmall); THR[$v]=24 ;;
    head256)
        # the head phantom in HU, 10 HU per step: skin (-500 HU) at 50
        DEN[$v]=$OUT/data/head256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$SW" export --phantom head --phantom-dims 256,256,256 --window -1000,1550 -o "${DEN[$v]}" >&2 ;;
    chest)
        # LIDC chest CT 512x512x48 at 0.57x0.57x5 mm, cubic voxels of 1.14 mm (VolPack has no spacing)
        DEN[$v]=$OUT/data/chest256.den; THR[$v]=50
        [ -f "${DEN[$v]}" ] || "$SW" export "$(data chest-ct-lung1.nrrd)" --window -1000,1550 --max-dim 256 -o "${DEN[$v]}" >&2 ;;
    mri)
        # Colin27 T1 MRI, 181x217x181 u8 at 1 mm: the skin surface
        DEN[$v]=$OUT/data/mri-ch2.den; THR[$v]=30
        [ -f "${DEN[$v]}" ] || "$SW" export "$(data head-mri-ch2.nii.gz)" -o "${DEN[$v]}" >&2 ;;
    *) log "unknown volume $v"; exit 1 ;;
    esac
done

for v in $VOLUMES; do
    for s in $SIZES; do
        for t in $THREADS; do
            base=$OUT/$v-$s-t$t
            args=(bench --den "${DEN[$v]}" --modes blend --peers vtk,volpack --size "$s" --threads "$t"
                --rounds "$ROUNDS" --reps "$REPS" --random-views "$RANDOM_VIEWS" --ref-step "$REF_STEP"
                --peer-dir "$base-frames" --csv "$base.csv" --json-out "$base.json" --plot "$base.svg" --quiet)
            [ -n "${THR[$v]}" ] && args+=(--iso "${THR[$v]}")
            [ -n "$PERSPECTIVE" ] && args+=(--perspective "$PERSPECTIVE")
            [ -n "${ONLY:-}" ] && args+=(--only "$ONLY")
            for d in ${DELUXE:-}; do args+=(--deluxe "$d"); done
            log "$v ${s}² $t thread(s)"
            "$SW" "${args[@]}" >"$base.md"
            grep -E "^- |^Model floor" "$base.md" | sed "s/^/$v ${s}² t$t: /" >&2 || true
        done
    done
done
