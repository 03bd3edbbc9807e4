#!/usr/bin/env bash
# Window test of `shearwarp view`: runs the real window under Xvfb, drives it with
# xdotool (mouse drag, held keys, clicks on the controls, a resize), takes
# screenshots with ImageMagick's `import` and checks them:
#   - the phantom is visible (the view area is not blank or uniform),
#   - the view changed after the drag, after each tissue switch, after Space,
#     after L (the focus+context lens),
#   - S saved a PNG, a resize re-rendered at the new size,
#   - an idle window uses no CPU (measured from /proc over a few seconds),
#   - Q quits and the process exits with status 0,
#   - `view --benchmark-drag 60` plays its scripted drag through the window, exits 0
#     and prints one JSON object with the frame rate (printed here),
#   - `view --needle` and `view --clip-box ... --clip-keep outside` open, show
#     something other than the plain view and quit; bad meshes and two outside
#     regions are usage errors (status 2) before any window.
# Screenshots and logs go to target/viewer-test/. Needs xvfb, xauth, xdotool,
# ImageMagick and jq; installs them with apt-get when missing (as root) and fails
# loudly when it cannot. Usage: tests/viewer.sh
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=target/viewer-test
BIN=target/release/shearwarp

if [[ "${1:-}" != --inner ]]; then
    have_tools() {
        local c
        for c in xvfb-run Xvfb xauth xdotool import compare identify convert jq; do
            command -v "$c" >/dev/null 2>&1 || return 1
        done
        # the real ImageMagick, not a stand-in
        import -version 2>/dev/null | grep -q ImageMagick
    }
    if ! have_tools; then
        echo "test-viewer: installing xvfb xauth xdotool imagemagick jq"
        if [[ $(id -u) -ne 0 ]] || ! command -v apt-get >/dev/null; then
            echo "test-viewer: FAIL: xvfb, xauth, xdotool, imagemagick and jq are missing and cannot be installed here (need root and apt-get)" >&2
            exit 1
        fi
        export DEBIAN_FRONTEND=noninteractive
        if ! { apt-get update -qq && apt-get install -y -qq xvfb xauth xdotool imagemagick jq >/dev/null; }; then
            echo "test-viewer: FAIL: apt-get install xvfb xauth xdotool imagemagick jq failed" >&2
            exit 1
        fi
        have_tools || { echo "test-viewer: FAIL: the window-test tools are still missing after apt-get" >&2; exit 1; }
    fi
    cargo build --release --quiet --features viewer
    rm -rf "$OUT"
    mkdir -p "$OUT"
    exec timeout 600 xvfb-run -a -e "$OUT/xvfb.err" -s "-screen 0 800x600x24" bash "$0" --inner
fi

# ---- inside Xvfb ----
LOG=$OUT/viewer.log
STDOUT=$OUT/stdout.log
PASS=0
FAIL=0
ok() { echo "ok - $*"; PASS=$((PASS + 1)); }
bad() { echo "FAIL - $*"; FAIL=$((FAIL + 1)); }
check() { # check DESCRIPTION COMMAND...
    local what=$1
    shift
    if "$@"; then ok "$what"; else bad "$what"; fi
}

"$BIN" view --verbose --size 512 --save-dir "$OUT" >"$STDOUT" 2>"$LOG" &
PID=$!
trap 'kill "$PID" 2>/dev/null || true' EXIT

alive() { kill -0 "$PID" 2>/dev/null; }
# wait_log REGEX [SECONDS]: until the viewer's log has a line matching REGEX
wait_log() {
    local t=0 lim=$((${2:-30} * 10))
    while ! grep -qE "$1" "$LOG"; do
        if ! alive; then
            echo "viewer died; log:" >&2
            cat "$LOG" >&2
            return 1
        fi
        t=$((t + 1))
        if ((t > lim)); then
            echo "timed out waiting for /$1/ in $LOG" >&2
            return 1
        fi
        sleep 0.1
    done
}
# count of log lines matching REGEX
nlog() { grep -cE "$1" "$LOG" || true; }
# wait_new REGEX N [SECONDS]: until more than N lines match
wait_new() {
    local t=0 lim=$((${3:-30} * 10))
    while (($(nlog "$1") <= $2)); do
        alive || { cat "$LOG" >&2; return 1; }
        t=$((t + 1))
        ((t <= lim)) || { echo "timed out waiting for a new /$1/" >&2; return 1; }
        sleep 0.1
    done
}
shot() { sleep 0.3; import -window "$WID" "$OUT/$1.png"; }
# the view area: below the text panel, above the controls (512×512 window)
VIEW="512x340+0+100"
stddev() { convert "$OUT/$1.png" -crop "$VIEW" +repage -colorspace Gray -format '%[fx:standard_deviation]' info:; }
# normalized RMS difference of the view areas of two shots
rmse() {
    convert "$OUT/$1.png" -crop "$VIEW" +repage "$OUT/.a.png"
    convert "$OUT/$2.png" -crop "$VIEW" +repage "$OUT/.b.png"
    # compare prints "ABS (NORMALIZED)" on stderr and exits 1 when the images differ
    compare -metric RMSE "$OUT/.a.png" "$OUT/.b.png" null: 2>&1 | sed -nE 's/^[0-9.e+-]+ \(([0-9.e+-]+)\)$/\1/p' || true
}
# gt A B: A > B, both numbers (anything else fails)
gt() {
    [[ "$1" =~ ^[0-9.e+-]+$ && "$2" =~ ^[0-9.e+-]+$ ]] || { echo "   not a number: '$1' or '$2'" >&2; return 1; }
    awk -v a="$1" -v b="$2" 'BEGIN { exit !(a + 0 > b + 0) }'
}
visible() { local s; s=$(stddev "$1"); echo "   $1: view-area standard deviation $s"; gt "$s" 0.05; }
differs() { local d; d=$(rmse "$1" "$2"); echo "   $1 vs $2: RMSE $d"; gt "$d" 0.01; }
hold() { # hold KEY: press for 150 ms (the window is focused first; no window manager here)
    xdotool windowfocus --sync "$WID"
    xdotool keydown "$1"
    sleep 0.15
    xdotool keyup "$1"
}
presented() { nlog '^presented '; }

# 1. the window appears with the phantom
WID=$(timeout 60 xdotool search --sync --name '^shearwarp view' | head -1) || true
[[ -n "$WID" ]] || { bad "a window titled 'shearwarp view' appears"; cat "$LOG"; exit 1; }
ok "the window appears (id $WID)"
wait_log '^presented seq=[0-9]+ kind=preview' 120
shot 01-start
check "the phantom is visible in the first frame" visible 01-start
same() { ! differs "$1" "$1"; }
check "the comparison finds no change between a shot and itself (control)" same 01-start
check "the window is 512x512" test "$(identify -format '%wx%h' "$OUT/01-start.png")" = 512x512

# 2. drag: rotate about the vertical and the horizontal eye axes, first slowly
# (about one mask bit per frame), then fast (the renderer catches up)
n=$(presented)
xdotool mousemove --window "$WID" 256 250 mousedown 1
for _ in $(seq 1 10); do
    xdotool mousemove_relative -- 2 0
    sleep 0.03
done
slow=$(nlog 'kind=preview .*steps=[1-6] direct=0')
for _ in $(seq 1 15); do
    xdotool mousemove_relative -- 8 3
    sleep 0.03
done
xdotool mouseup 1
wait_new '^presented ' "$n"
sleep 0.5
shot 02-dragged
check "the view changed after the drag" differs 01-start 02-dragged
check "the slow drag was rendered by incremental one-bit shears ($slow frames)" test "$slow" -gt 0
echo "   drag frames: $(nlog 'kind=preview .*steps=[1-6] direct=0') incremental, $(nlog 'kind=preview .*direct=1') direct shears"

# 3. tissue key 4 (bone), held
hold 4
wait_log '^presented .*tissue=bone'
shot 03-bone-key
check "key 4 switched to bone" grep -q 'frame .*tissue=bone' "$LOG"
check "the image changed after the tissue switch" differs 02-dragged 03-bone-key

# 4. click the second tissue button (fat); its place comes from the layout line
b=$(grep -oE 'button1=[0-9]+,[0-9]+,[0-9]+,[0-9]+' "$LOG" | tail -1 | cut -d= -f2)
IFS=, read -r bx by bw bh <<<"$b"
xdotool mousemove --window "$WID" $((bx + bw / 2)) $((by + bh / 2)) click 1
wait_log '^presented .*tissue=fat'
shot 04-fat-click
check "clicking the tissue button switched tissues" differs 03-bone-key 04-fat-click

# 5. Space: the full alpha-blended render replaces the preview in the background
hold space
wait_log '^presented .*kind=blend' 60
shot 05-blend
check "Space showed the alpha-blended render" differs 04-fat-click 05-blend
check "the blended frame is visible" visible 05-blend

# 6. the iso slider: a custom threshold rebuilds the mask (shown as busy), window stays live
s=$(grep -oE 'slider=[0-9]+,[0-9]+,[0-9]+,[0-9]+' "$LOG" | tail -1 | cut -d= -f2)
IFS=, read -r sx sy sw sh <<<"$s"
xdotool mousemove --window "$WID" $((sx + sw * 45 / 100)) $((sy + sh / 2)) click 1
wait_log '^presented .*kind=blend .*tissue=custom' 60
shot 06-custom-iso
check "the slider set a custom iso value (mask rebuilt)" grep -q 'busy kind=preview .*rebuilding mask for iso' "$LOG"
check "the custom iso image differs" differs 05-blend 06-custom-iso

# 7. '+' twice: super-cell size 3 (lossless: the picture stays, only speed changes)
hold plus
wait_log '^presented .*cell=2'
hold plus
wait_log '^presented .*cell=3'
ok "+ raised the super-cell size to 3"

# 8. S saves the current view and prints its path
hold s
t=0
until grep -q '^saved ' "$STDOUT" || ((t > 50)); do sleep 0.1; t=$((t + 1)); done
saved=$(sed -nE 's/^saved ([^ ]+) .*/\1/p' "$STDOUT" | head -1)
check "S saved a PNG ($saved)" test -s "$saved"
[[ -s "$saved" ]] && cp "$saved" "$OUT/07-saved.png"

# 9. resize: re-rendered at the new size
xdotool windowsize "$WID" 640 400
wait_log '^presented .*size=640x400' 60
shot 08-resized
check "the window re-rendered at 640x400" test "$(identify -format '%wx%h' "$OUT/08-resized.png")" = 640x400

# 10. R resets the view
n=$(presented)
hold r
wait_new '^presented ' "$n"
sleep 1

# 10b. L: a bone lens (focus+context) on the skin, under the mouse at the depth
# of the volume centre; L again removes it
hold 1
wait_log '^presented .*tissue=skin' 60
xdotool mousemove --window "$WID" 320 190
sleep 1.5
shot 10-skin
n=$(presented)
hold l
wait_new '^presented ' "$n"
sleep 1.5
shot 11-lens
check "L put a lens on the view (the frame changed)" differs 10-skin 11-lens
n=$(presented)
hold l
wait_new '^presented ' "$n"
sleep 1

# 11. idle: no CPU while nothing changes
hz=$(getconf CLK_TCK)
sleep 2 # let the background blend and the idle mask prefetch finish
t0=$(awk '{ print $14 + $15 }' "/proc/$PID/stat")
sleep 5
t1=$(awk '{ print $14 + $15 }' "/proc/$PID/stat")
idle=$(awk -v d=$((t1 - t0)) -v hz="$hz" 'BEGIN { printf "%.2f", 100 * d / hz / 5 }')
echo "   idle: $((t1 - t0)) ticks in 5 s = ${idle}% CPU; ps: $(ps -o %cpu=,time= -p "$PID")"
check "an idle window uses < 1% CPU (${idle}%)" gt 1 "$idle"
shot 09-reset-idle
check "the reset view is visible" bash -c "convert '$OUT/09-reset-idle.png' -crop 640x240+0+100 +repage -colorspace Gray -format '%[fx:standard_deviation]' info: | awk '{ exit !(\$1 > 0.05) }'"

# 12. Q quits
hold q
t=0
while alive && ((t < 100)); do sleep 0.1; t=$((t + 1)); done
if alive; then
    bad "Q quit the viewer"
else
    rc=0
    wait "$PID" || rc=$?
    check "Q quit the viewer (exit status $rc)" test "$rc" -eq 0
fi
trap - EXIT

# 13. --benchmark-drag: a scripted drag of 60 frames through the window path
# (state, preview worker, softbuffer present), then one JSON object on stdout
BENCH=$OUT/benchmark.json
rc=0
timeout 120 "$BIN" view --benchmark-drag 60 --size 512 >"$BENCH" 2>"$OUT/benchmark.err" || rc=$?
check "view --benchmark-drag 60 exited with status 0 within 120 s (status $rc)" test "$rc" -eq 0
# jq -e fails on anything but a number; one line, one object
num() { jq -er "select(type == \"object\") | .$1 | numbers" "$BENCH" 2>/dev/null || true; }
fps=$(num fps)
fms=$(num frame_ms_median)
objects=$(jq -s 'length' "$BENCH" 2>/dev/null || echo invalid)
echo "   benchmark drag (512x512, head phantom): fps $fps, frame_ms_median $fms, $(jq -r '"render \(.render_ms_median) ms, present \(.present_ms_median) ms, \(.frames) frames"' "$BENCH" 2>/dev/null || true)"
check "--benchmark-drag printed one JSON object ($objects, $(wc -l <"$BENCH") line)" test "$objects" = 1 -a "$(wc -l <"$BENCH")" -eq 1
check "--benchmark-drag reported fps > 0 ($fps) and frame_ms_median > 0 ($fms)" bash -c "$(declare -f gt); gt '$fps' 0 && gt '$fms' 0"
check "--benchmark-drag rendered and presented all 60 frames, none skipped" test "$(num frames)/$(num skipped_frames)" = 60/0

# 14. geometry and clip regions: `view --needle` and `view --clip-box
# ... --clip-keep outside` open, draw something other than the plain view, and
# quit cleanly; bad scene input is a usage error (status 2) before any window
# scene_view NAME ARGS...: opens the viewer with ARGS, saves shot NAME, quits with Q
scene_view() {
    local name=$1
    shift
    LOG=$OUT/$name.log
    "$BIN" view --verbose --size 512 "$@" >"$OUT/$name.out" 2>"$LOG" &
    PID=$!
    trap 'kill "$PID" 2>/dev/null || true' EXIT
    WID=$(timeout 60 xdotool search --sync --name '^shearwarp view' | head -1) || true
    [[ -n "$WID" ]] || { echo "   no window for $name" >&2; return 1; }
    wait_log '^presented seq=[0-9]+ kind=preview' 120 || return 1
    sleep 1
    shot "$name"
    hold q
    local t=0
    while alive && ((t < 100)); do sleep 0.1; t=$((t + 1)); done
    alive && { echo "   $name: Q did not quit" >&2; return 1; }
    local rc=0
    wait "$PID" || rc=$?
    trap - EXIT
    echo "   $name: exit status $rc"
    test "$rc" -eq 0
}
check "view (plain, for comparison) opened, rendered and quit" scene_view 20-plain
check "view --needle opened, rendered and quit" scene_view 21-needle --needle=-30,64,56,160,64,70,3
check "view --clip-box ... --clip-keep outside opened, rendered and quit" scene_view 22-clip-box --clip-box 0,0,0,90,127,112 --clip-keep outside
check "the needle shows (the view differs from the plain one)" differs 20-plain 21-needle
check "the box is cut out (the view differs from the plain one)" differs 20-plain 22-clip-box
check "the clipped view is visible" visible 22-clip-box
usage_rc() { # usage_rc ARGS...: the viewer refuses ARGS with status 2 and no panic
    local rc=0
    timeout 60 "$BIN" view "$@" >/dev/null 2>"$OUT/usage.err" || rc=$?
    echo "   view $*: status $rc: $(head -1 "$OUT/usage.err")"
    test "$rc" -eq 2 && ! grep -q panicked "$OUT/usage.err"
}
printf 'v 0 0 0\nv 1 0 0\nf 1 2 7\n' >"$OUT/garbled.obj"
printf 'v 40 40 40\nv 80 40 40\nv 80 80 40\nv 40 80 40\nv 40 40 80\nv 80 40 80\nv 80 80 80\nv 40 80 80\nf 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n' >"$OUT/cube.obj"
check "view --mesh with a missing file is a usage error" usage_rc --mesh "$OUT/no-such-mesh.obj"
check "view --mesh with a garbled file is a usage error" usage_rc --mesh "$OUT/garbled.obj"
check "view with two regions keeping their outside is a usage error" usage_rc --clip-box 0,0,0,90,127,112 --clip-mesh "$OUT/cube.obj" --clip-keep outside

echo "screenshots and logs: $OUT/"
echo "test-viewer: $PASS passed, $FAIL failed"
((FAIL == 0))
