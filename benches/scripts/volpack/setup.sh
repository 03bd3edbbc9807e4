# setup.sh -- sourced (not run) by benches/scripts/compare-volpack.sh and
# benches/scripts/compare-rotators.sh after they set ROOT: logging, root and apt-get
# helpers, the VolPack harness build and the search for brainsmall.den.

log() { printf '%s\n' "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"
    elif command -v sudo >/dev/null 2>&1; then sudo "$@"
    else log "need root to run: $*"; exit 1
    fi
}

apt_install() {
    # try without touching the package lists first; update only if needed
    if ! as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "$@" >&2; then
        log "apt-get install failed; running apt-get update and retrying"
        as_root apt-get update >&2
        as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "$@" >&2
    fi
}

# volpack_harness BIN: installs libvolpack1-dev (and build-essential without a
# C compiler) when missing, and builds BIN from benches/scripts/volpack/harness.c when
# BIN is missing or older than the source.
volpack_harness() {
    local bin=$1 src=$ROOT/benches/scripts/volpack/harness.c need=()
    dpkg -s libvolpack1-dev >/dev/null 2>&1 || need+=(libvolpack1-dev)
    command -v cc >/dev/null 2>&1 || need+=(build-essential)
    if [ ${#need[@]} -gt 0 ]; then
        log "installing: ${need[*]}"
        apt_install "${need[@]}"
    fi
    if [ ! -x "$bin" ] || [ "$src" -nt "$bin" ]; then
        log "building $bin"
        cc -O2 -Wall -o "$bin" "$src" -lvolpack -lm
    fi
}

# find_brainsmall: prints the path of the first brainsmall.den found (the
# shared data directory, else the copy in libvolpack1-dev's examples).
find_brainsmall() {
    local c
    for c in "$ROOT/shared/data/brainsmall.den" "$ROOT/../shared/data/brainsmall.den" \
             /work/shared/data/brainsmall.den /usr/share/doc/libvolpack1-dev/examples/brainsmall.den; do
        if [ -f "$c" ]; then realpath "$c"; return 0; fi
    done
    return 1
}
