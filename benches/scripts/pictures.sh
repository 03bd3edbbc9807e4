#!/usr/bin/env bash
# Renders the README's pictures of real scans into benches/pictures/ (256×256 PNGs).
#
#   benches/scripts/pictures.sh            # scans from ${SHEARWARP_DATA:-../shared/data}
#   SHEARWARP_DATA=/path/to/scans benches/scripts/pictures.sh
#
# The scans are the public sample volumes that tests/fetch-data.sh downloads
# (chest-ct-lung1.nrrd, head-mri-ch2.nii.gz); they are inputs only and are never
# committed. Only the rendered PNGs are.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
data="${SHEARWARP_DATA:-../shared/data}"
out="benches/pictures"

for f in chest-ct-lung1.nrrd head-mri-ch2.nii.gz; do
    if [[ ! -e "$data/$f" ]]; then
        echo "missing $data/$f: set SHEARWARP_DATA or run tests/fetch-data.sh DIR" >&2
        exit 1
    fi
done

cargo build --release
bin="target/release/shearwarp"
mkdir -p "$out"

render() {
    local name="$1"
    shift
    "$bin" render "$@" --size 256 --quiet -o "$out/$name.png"
}

# T1 MRI head (Colin27, 181×217×181, 1 mm): the skin surface (lowest histogram preset), three-quarter view
render mri-head-skin "$data/head-mri-ch2.nii.gz" --tissue low --rotate 12,-35,0 --zoom 1.05
# the same MRI cut by a clipping plane above the ventricles, seen from above: the brain's folds
render mri-brain-clip "$data/head-mri-ch2.nii.gz" --tissue mid --clip-plane 0,0,1,105 --view superior --rotate -30,0,0 --zoom 0.95
# chest CT (512×512×48, 5 mm slices, Hounsfield units): bone preset from behind, spine, ribs and shoulder blades
render chest-ct-bone "$data/chest-ct-lung1.nrrd" --tissue bone --view posterior --zoom 0.75
# the same CT alpha-blended through the bone preset's transfer function, from the front
render chest-ct-blend "$data/chest-ct-lung1.nrrd" --tissue bone --mode blend --zoom 0.75

ls -l "$out"/*.png
