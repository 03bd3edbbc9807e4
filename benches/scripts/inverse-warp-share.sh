#!/usr/bin/env bash
# The inverse warp's share of the frame (the goal: at most 5 % at 512²), the 16 cases of
# README's tables: the head phantom and the chest CT, parallel and --perspective 40, binary iso
# and RLE blend, skin and bone, each a 30° turn with `rotate --json`. One line a case: the
# inverse warp's median µs, its share of the volume's frame and of the whole frame (meshes'
# drawing and composite included), and the volume frame's median ms.
# Usage: benches/scripts/inverse-warp-share.sh [BINARY]   (default: target/release/shearwarp)
# Env: SHEARWARP_DATA (the chest CT; without it only the head runs), DIR (scratch, for the needles)
set -euo pipefail
cd "$(dirname "$0")/../.."
B=${1:-target/release/shearwarp}
[ -x "$B" ] || cargo build --release --quiet
DIR=${DIR:-target/inverse-warp-share}
mkdir -p "$DIR"
python3 benches/scripts/cylinder-obj.py 10 30 20 118 100 95 2 "$DIR/needle-head.obj"
python3 benches/scripts/cylinder-obj.py 40 100 5 470 400 42 6 "$DIR/needle-chest.obj"
CHEST="${SHEARWARP_DATA:-}/chest-ct-lung1.nrrd"
for vol in head chest; do
  if [ $vol = head ]; then V=(--phantom head); N="$DIR/needle-head.obj"; else
    [ -f "$CHEST" ] || { echo "chest: no $CHEST (set SHEARWARP_DATA)" >&2; continue; }
    V=("$CHEST"); N="$DIR/needle-chest.obj"; fi
  for proj in "" "--perspective 40"; do
    for m in "--method binary" "--method rle --mode blend"; do
      for t in "" "--tissue bone"; do
        # shellcheck disable=SC2086
        "$B" rotate "${V[@]}" --mesh "$N" $proj $m $t --size 512 --degrees 30 --json 2>/dev/null | python3 -c "
import json, sys
j = json.load(sys.stdin); g = j['geometry']
print('%-6s %-16s %-26s %-13s inverse warp %6.1f µs  share %5.2f %%  of the whole frame %5.2f %%  volume frame %6.2f ms' % (
    '$vol', '$proj' or 'parallel', '$m', '$t' or 'skin', g['inverse_warp_ms_median'] * 1e3,
    g['inverse_warp_share_median'] * 100, g['inverse_warp_share_of_scene_frame_median'] * 100, j['frame_ms_median']))"
      done
    done
  done
done
