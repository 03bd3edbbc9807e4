#!/usr/bin/env bash
# Reproduces Tables 1–4 of Csébfalvi (1999) on this machine with `shearwarp rotate --json`:
#   Tables 1/2: iso preview (bone threshold, as in the paper) per cell size 1–4 — shear ms,
#               render ms, frame rate, effective rotation speed (the view moves s bits per frame);
#   Tables 3/4: alpha-blending render times for transfer functions A, B, C (skin, soft, bone).
# Usage: benches/scripts/paper-tables.sh [extra shearwarp args, e.g. a FILE or --threads 2]
# Env: SIZES="128,128,113 256,256,225" (phantom dims), CELLS="1 2 3 4", THREADS=1, OUT=512.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet
B=target/release/shearwarp
SIZES=${SIZES:-"128,128,113 256,256,225"}
CELLS=${CELLS:-"1 2 3 4"}
THREADS=${THREADS:-1}
OUT=${OUT:-512}
run() { "$B" rotate --quiet --json --threads "$THREADS" --size "$OUT" "$@"; }

volumes=()
if [ $# -gt 0 ]; then volumes+=("custom"); else for d in $SIZES; do volumes+=("$d"); done; fi
for v in "${volumes[@]}"; do
  if [ "$v" = custom ]; then vargs=("$@"); label="$*"; else vargs=(--phantom head --phantom-dims "$v"); label="head phantom $v"; fi
  echo
  echo "### Iso preview (bone), $label, ${OUT}², $THREADS thread(s)"
  echo
  echo "| cell size | shear ms | render ms | warp ms | frame rate (Hz) | degrees/s | step (°/frame) |"
  echo "|---|---|---|---|---|---|---|"
  for s in $CELLS; do
    run "${vargs[@]}" --tissue bone --cell "$s" --degrees 90 | python3 -c '
import json,sys; j=json.load(sys.stdin)
print("| %d | %.3f | %.3f | %.3f | %.1f | %.0f | %.3f |" % (j["cell"], j["shear_ms_median"], j["render_ms_median"], j["warp_ms_median"], j["fps"], j["degrees_per_second"], j["step_deg"]))'
  done
  echo
  echo "### Alpha blending render ms (median), $label, ${OUT}², $THREADS thread(s)"
  echo
  echo "| cell size | A (skin) | B (soft tissue) | C (bone) |"
  echo "|---|---|---|---|"
  for s in $CELLS; do
    row="| $s |"
    for t in skin soft bone; do
      ms=$(run "${vargs[@]}" --mode blend --tissue "$t" --cell "$s" --degrees 30 | python3 -c 'import json,sys; print("%.2f" % json.load(sys.stdin)["render_ms_median"])')
      row="$row $ms |"
    done
    echo "$row"
  done
done
