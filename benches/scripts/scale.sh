#!/usr/bin/env bash
# scale.sh -- how the binary iso rotation's time per frame grows with volume
# size (head phantom 128³, 256³, 512³) and output size (256², 512², 1024²),
# for 1 thread and all cores: a table of median ms per frame with its split
# into shear / render / warp, and the mask's bytes.
#
#   benches/scripts/scale.sh                      # 90 frames per run
#   FRAMES=30 DIMS="128 256" benches/scripts/scale.sh
#   EXTRA="--cell 4" benches/scripts/scale.sh     # super cells
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
FRAMES=${FRAMES:-90}
DIMS=${DIMS:-128 256 512}
SIZES=${SIZES:-256 512 1024}
THREADS=${THREADS:-1 0}
EXTRA=${EXTRA:-}
SW=$ROOT/target/release/shearwarp
(cd "$ROOT" && cargo build --release --quiet)

echo "head phantom, skin iso, --view superior --axis y, $FRAMES frames of 1°, $(nproc) cores${EXTRA:+, $EXTRA}"
echo
echo "| volume | image | threads | frame ms | shear ms | render ms | warp ms | mask MB | first-axis build ms |"
echo "|---|---|---:|---:|---:|---:|---:|---:|---:|"
for n in $DIMS; do
    for s in $SIZES; do
        for t in $THREADS; do
            # shellcheck disable=SC2086  # EXTRA is a flag list
            j=$("$SW" rotate --phantom head --phantom-dims "$n,$n,$n" --tissue skin --view superior --axis y \
                --degrees "$FRAMES" --step-deg 1 --size "$s" --threads "$t" --quiet --json $EXTRA)
            printf '%s' "$j" | python3 -c "
import json, sys
j = json.load(sys.stdin)
t = '$t' if '$t' != '0' else 'all'
print(f\"| {$n}³ | {$s}² | {t} | {j['frame_ms_median']:.2f} | {j['shear_ms_median']:.2f} | {j['render_ms_median']:.2f} | {j['warp_ms_median']:.2f} | {j['mask_bytes'] / 1e6:.1f} | {j['build_ms']:.0f} |\")"
        done
    done
done
