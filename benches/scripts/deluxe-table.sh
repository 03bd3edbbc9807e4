#!/usr/bin/env bash
# Reproduces Table 1 of Sweeney & Mueller, "Shear-Warp Deluxe" (2002) on this machine,
# with the error beside every time.
#   Rows:    the cube 64³ and the engine-like block 128³ (phantoms), the head phantom at 128³
#            (or volumes of your own: VOLUMES="label|args …"), each on the cartesian and the
#            BCC grid.
#   Columns: S at the volume-sized image (about one pixel per voxel: the bounding diagonal
#            in pixels), then S, I, IP, IM, IMP at OUT² (512²).
#   Cells:   frame ms (median) / RMSE / SSIM against the project's reference renderer, at
#            0°, 45° and along the main diagonal (the hardest view).
# Blend mode, the phantom's own iso value (VolPack-like ramp from presets::generic), one
# thread by default (the paper's single CPU). A cell a path cannot render prints "–".
# Usage: benches/scripts/deluxe-table.sh            (writes target/deluxe-table/table.md)
# Env: OUT=512 THREADS=1 ROUNDS=3 REPS=3 DIR=target/deluxe-table VOLUMES=...
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --release --quiet
B=target/release/shearwarp
OUT=${OUT:-512}
THREADS=${THREADS:-1}
ROUNDS=${ROUNDS:-3}
REPS=${REPS:-3}
DIR=${DIR:-target/deluxe-table}
mkdir -p "$DIR"
if [ -z "${VOLUMES:-}" ]; then
  VOLUMES="cube 64³|--phantom cube
engine 128³|--phantom engine
head phantom 128³|--phantom head --phantom-dims 128,128,128 --iso 50"
fi

COLUMNS="rle,rle-deluxe-I,rle-deluxe-IP,rle-deluxe-IM,rle-deluxe-IMP,rle-bcc,rle-bcc-deluxe-I,rle-bcc-deluxe-IP,rle-bcc-deluxe-IM,rle-bcc-deluxe-IMP"
bench() { "$B" bench --quiet --modes blend --random-views 0 --threads "$THREADS" --rounds "$ROUNDS" --reps "$REPS" "$@"; }

i=0
while IFS='|' read -r label args; do
  [ -n "$label" ] || continue
  i=$((i + 1))
  # shellcheck disable=SC2086
  native=$("$B" info --json ${args%% --iso*} | python3 -c 'import json,sys,math; d=json.load(sys.stdin)["dims"]; print(math.ceil(math.sqrt(sum((n-1)**2 for n in d))))')
  echo "[$label] S at ${native}² and the options at ${OUT}² …" >&2
  # shellcheck disable=SC2086
  bench $args --size "$native" --only rle,rle-bcc --json-out "$DIR/v$i-native.json" > /dev/null
  # shellcheck disable=SC2086
  bench $args --size "$OUT" --only "$COLUMNS" --json-out "$DIR/v$i-out.json" > /dev/null
  printf '%s|%s|%s\n' "$i" "$label" "$native" >> "$DIR/volumes.$$"
done <<< "$VOLUMES"

python3 - "$DIR" "$OUT" "$THREADS" "$DIR/volumes.$$" > "$DIR/table.md" <<'EOF'
import json, sys
d, out, threads, vols = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
views = [("0°", "0°"), ("45°", "45°"), ("diagonal", "diagonal")]
cols = ["S", "I", "IP", "IM", "IMP"]
def cell(recs, variant, view):
    r = recs.get((variant, view))
    if r is None:
        return "–"
    return "%.2f / %.4f / %.3f" % (r["frame_ms"], r["error"]["rmse"], r["error"]["ssim"])
print("Shear-Warp Deluxe, Table 1 on this machine: frame ms / RMSE / SSIM against the reference "
      "(blend, %s thread(s)); S at about one pixel per voxel, then %s² with the options.\n" % (threads, out))
print("| data | grid | view | S (native) | " + " | ".join("%s (%s²)" % (c, out) for c in cols) + " |")
print("|---|---|---|---:|" + "---:|" * len(cols))
skipped = []
for line in open(vols):
    i, label, native = line.rstrip("\n").split("|")
    reps = {}
    for tag in ("native", "out"):
        j = json.load(open("%s/v%s-%s.json" % (d, i, tag)))
        reps[tag] = {(r["variant"], r["view"]): r for r in j["records"]}
        skipped += ["%s, %s: %s" % (label, s["variant"], s["reason"]) for s in j.get("skipped", [])]
    for grid, prefix in (("cartesian", "rle"), ("BCC", "rle-bcc")):
        for vname, key in views:
            row = [cell(reps["native"], prefix, key) + " @%s²" % native]
            for c in cols:
                variant = prefix if c == "S" else "%s-deluxe-%s" % (prefix, c)
                row.append(cell(reps["out"], variant, key))
            print("| %s | %s | %s | %s |" % (label, grid, vname, " | ".join(row)))
if skipped:
    print("\nNot rendered:")
    for s in sorted(set(skipped)):
        print("- " + s)
EOF
rm -f "$DIR/volumes.$$"
cat "$DIR/table.md"
