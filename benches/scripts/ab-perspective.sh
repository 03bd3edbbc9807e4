#!/usr/bin/env bash
# ab-perspective.sh OLD NEW [VOLUME ARGS...] -- interleaved A/B of two shearwarp
# binaries, each in a parallel and a perspective frame of the same volume and
# image: every round runs OLD then NEW, each parallel then perspective; the
# table gives the median of the rounds' frame_ms_median for all four, NEW/OLD
# per projection, and the perspective/parallel ratio of each binary (the
# ratio that matters for perspective, measured side by side in one run).
#
#   benches/scripts/ab-perspective.sh /tmp/old target/release/shearwarp --phantom head
#   ROUNDS=3 benches/scripts/ab-perspective.sh OLD NEW "$SHEARWARP_DATA/chest-ct-lung1.nrrd"
#   METHOD="--method rle --mode blend" benches/scripts/ab-perspective.sh OLD NEW --phantom head
#
# Environment: ROUNDS (5), THREADS (1), SIZE (512), DEGREES (30, in 1° steps),
# PERSPECTIVE ("--perspective 30 --eye-distance 2"), METHOD (the binary
# rotator's iso preview: empty).
set -euo pipefail
OLD=$(realpath "$1")
NEW=$(realpath "$2")
shift 2
ROUNDS=${ROUNDS:-5}
THREADS=${THREADS:-1}
SIZE=${SIZE:-512}
DEGREES=${DEGREES:-30}
PERSPECTIVE=${PERSPECTIVE:---perspective 30 --eye-distance 2}
METHOD=${METHOD:-}
raw=$(mktemp)
trap 'rm -f "$raw"' EXIT
for _ in $(seq "$ROUNDS"); do
    for b in old new; do
        bin=$OLD
        [ "$b" = new ] && bin=$NEW
        for p in parallel perspective; do
            extra=()
            # shellcheck disable=SC2206
            [ "$p" = perspective ] && extra=($PERSPECTIVE)
            # shellcheck disable=SC2086
            ms=$("$bin" rotate "$@" $METHOD --size "$SIZE" --threads "$THREADS" --degrees "$DEGREES" --step-deg 1 \
                --quiet --json "${extra[@]}" | tr -d '\n' | sed -n 's/.*"frame_ms_median"[[:space:]]*:[[:space:]]*\([-0-9.eE+]*\).*/\1/p')
            echo "$b-$p $ms" >> "$raw"
        done
    done
done
awk '
    { v[$1] = v[$1] " " $2 }
    function median(s,   a, n, i, j, t) {
        n = split(s, a, " ")
        for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
        return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2
    }
    END {
        for (k in v) m[k] = median(v[k])
        printf "| | old ms | new ms | new/old |\n|---|---:|---:|---:|\n"
        printf "| parallel | %.3f | %.3f | %.3f |\n", m["old-parallel"], m["new-parallel"], m["new-parallel"] / m["old-parallel"]
        printf "| perspective | %.3f | %.3f | %.3f |\n", m["old-perspective"], m["new-perspective"], m["new-perspective"] / m["old-perspective"]
        printf "| perspective / parallel | %.2f | %.2f | |\n", m["old-perspective"] / m["old-parallel"], m["new-perspective"] / m["new-parallel"]
    }' "$raw"
