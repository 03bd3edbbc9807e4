#!/usr/bin/env bash
# scale.sh -- how a clinical-size scan's first frame, memory and steady frame
# time grow with volume size, beside VolPack's preprocessing and
# per-frame time for the same volumes and iso surface.
#
# For each volume (all 8-bit .den files, so VolPack reads the same voxels):
#   - `shearwarp render` (one frame, process start to PNG written): load ms,
#     build ms, first-frame ms, peak resident memory (/usr/bin/time and VmHWM);
#   - `shearwarp rotate` (FRAMES frames of 1° about y, 1 thread and all cores):
#     build ms of the first axis per structure, first-frame ms, median frame
#     ms, the renderer's memory per structure, peak resident memory;
#   - VolPack (`benches/scripts/volpack/harness.c`, opaque ramp at T, the same
#     iso surface as shearwarp --iso T+2): preprocessing ms, median frame ms,
#     peak resident memory.
#
#   benches/scripts/scale.sh                     # 128³, 256³, chest 512×512×413, 512³
#   VOLUMES="head128 chest512" FRAMES=30 benches/scripts/scale.sh
#   NO_VOLPACK=1 benches/scripts/scale.sh        # shearwarp only
#
# Environment: VOLUMES (head128 head256 chest512 head512), FRAMES (60),
# SIZE (512), OUT (target/scale). The chest comes from
# ../shared/data/chest-ct-lung1.nrrd resampled to isotropic 0.57 mm voxels
# (`export --window -1000,1550 --max-dim 512`); skipped if the file is absent.
# Output: a Markdown table on stdout, every JSON line in $OUT/runs.jsonl.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
OUT=${OUT:-$ROOT/target/scale}
FRAMES=${FRAMES:-60}
SIZE=${SIZE:-512}
VOLUMES=${VOLUMES:-head128 head256 chest512 head512}
SW=$ROOT/target/release/shearwarp
VP=$OUT/volpack-harness
mkdir -p "$OUT/data"

# shellcheck source=volpack/setup.sh
. "$ROOT/benches/scripts/volpack/setup.sh"
(cd "$ROOT" && cargo build --release --quiet)
[ -n "${NO_VOLPACK:-}" ] || volpack_harness "$VP"
command -v /usr/bin/time >/dev/null || apt_install time

CHEST=""
for c in "${SHEARWARP_DATA:-/nonexistent}/chest-ct-lung1.nrrd" "$ROOT/../shared/data/chest-ct-lung1.nrrd" /work/shared/data/chest-ct-lung1.nrrd; do
    [ -f "$c" ] && { CHEST=$(realpath "$c"); break; }
done

# volumes: name -> .den (the head phantom in HU, 10 HU per step: skin at 50)
declare -A DEN
for v in $VOLUMES; do
    f=$OUT/data/$v.den
    case $v in
    head*) n=${v#head}; [ -f "$f" ] || "$SW" export --phantom head --phantom-dims "$n,$n,$n" --window -1000,1550 -o "$f" >&2 ;;
    chest512)
        [ -n "$CHEST" ] || { log "chest-ct-lung1.nrrd not found: skipping chest512"; continue; }
        [ -f "$f" ] || "$SW" export "$CHEST" --window -1000,1550 --max-dim 512 -o "$f" >&2 ;;
    *) log "unknown volume $v"; exit 1 ;;
    esac
    DEN[$v]=$f
done

T=50          # VolPack's opaque ramp clamp((d - T)/4, 0, 1) reaches 0.5 at T + 2
ISO=$((T + 2))
RUNS=$OUT/runs.jsonl
: >"$RUNS"

# timed CMD...: runs CMD, prints its stdout, appends "peak_kb N" to $OUT/peak
timed() { /usr/bin/time -f "%M" -o "$OUT/peak" "$@"; }
field() { python3 -c "import json,sys; j=json.loads(sys.stdin.read()); print($1)"; }

ROWS=()
for v in $VOLUMES; do
    den=${DEN[$v]:-}
    [ -n "$den" ] || continue
    raw=$(stat -c %s "$den")
    dims=$("$SW" info "$den" --json | field "'×'.join(map(str, j['dims']))")
    log "== $v $dims"
    j=$(timed "$SW" render "$den" --iso "$ISO" --view superior --size "$SIZE" --json -q -o "$OUT/$v.png")
    printf '{"run":"render","volume":"%s",%s\n' "$v" "${j#\{}" >>"$RUNS"
    r_peak=$(cat "$OUT/peak")
    r=$(printf '%s' "$j" | field "'%.0f|%.0f|%.0f' % (j['load_ms'], j['build_ms'], j['first_frame_ms'])")
    declare -A ROT=()
    for thr in 1 0; do
        j=$(timed "$SW" rotate "$den" --iso "$ISO" --view superior --axis y --degrees "$FRAMES" --step-deg 1 \
            --size "$SIZE" --threads "$thr" --quiet --json)
        printf '{"run":"rotate","volume":"%s",%s\n' "$v" "${j#\{}" >>"$RUNS"
        ROT[$thr]=$(printf '%s' "$j" | field "'%.0f|%.2f|%.0f|%s' % (j['first_frame_ms'], j['frame_ms_median'], j['memory']['total'] / 2**20, \
            '/'.join('%.0f' % (sum(j['memory'][k]) / 2**20) for k in ['stacks', 'normals', 'cell_codes', 'masks']))")
        ROT[peak$thr]=$(cat "$OUT/peak")
    done
    vp="-|-|-"
    if [ -z "${NO_VOLPACK:-}" ]; then
        if j=$(timed "$VP" --den "$den" --size "$SIZE" --tf opaque --threshold "$T" --frames "$FRAMES" --step-deg 1); then
            printf '%s\n' "$j" >>"$RUNS"
            vp=$(printf '%s' "$j" | field "'%.0f|%.2f' % (j['preprocess_ms'], j['frame_ms_median'])")"|$(( $(cat "$OUT/peak") / 1024 ))"
        fi
    fi
    IFS='|' read -r load build first <<<"$r"
    IFS='|' read -r rfirst1 frame1 mem1 parts1 <<<"${ROT[1]}"
    IFS='|' read -r rfirstN frameN _ _ <<<"${ROT[0]}"
    IFS='|' read -r vpre vframe vpeak <<<"$vp"
    ROWS+=("| $v | $dims | $((raw / 1048576)) | $load | $build | $first | $rfirstN | $((r_peak / 1024)) | $((${ROT[peak0]} / 1024)) | $mem1 ($parts1) | $frame1 | $frameN | $vpre | $vframe | $vpeak |")
done

echo
echo "Binary iso preview (--iso $ISO, --view superior), ${SIZE}², $FRAMES frames of 1° about y; $(nproc) cores,"
echo "$(date -u +%Y-%m-%dT%H:%MZ), $(git -C "$ROOT" rev-parse --short HEAD). Times in ms, memory in MiB."
echo "render: one frame, process start to PNG written, all cores. rotate: median frame, 1 thread / all cores."
echo "Held = the renderer's structures after the run (volume + stacks/normals/cell codes/masks + intermediate)."
echo "VolPack: opaque ramp at T=$T, one thread; its preprocessing is classification + run-length encoding."
echo
echo "| volume | dims | raw MiB | load | build | first frame (render) | first frame (rotate, all) | peak MiB render | peak MiB rotate | held MiB (stacks/normals/cell codes/masks) | frame 1 thr | frame all | VolPack preprocess | VolPack frame | VolPack peak MiB |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"
printf '%s\n' "${ROWS[@]}"
echo
echo "every JSON line: $RUNS"
