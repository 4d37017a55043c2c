#!/usr/bin/env bash
# Downloads the wheels the GPU machine needs to run pdsim (it has Python 3.12, numpy and scipy, and no registry) and
# packs them for tools/gpu_suite.sh: one tar of the wheels, split into parts under 60 MB (the files sent with one
# command are limited to 64 MiB, the working tree included), each part in a folder of its own under .gpu_wheels/
# (ignored by git), with a manifest (part names and SHA-256 sums).
#
#   bash tools/gpu_wheels.sh                 # the wheels of the GPU suite, parts of 55 MB
#   PACKAGES="tqdm" PART_MB=0.03 DEST=/tmp/w bash tools/gpu_wheels.sh   # a small trial (the split and the manifest)
#
# Each command on the GPU machine carries the manifest and one or more parts (carry: .gpu_wheels/manifest.sha256 and
# .gpu_wheels/part01, ...); the parts stay on the machine between its commands while it is held, and gpu_suite.sh
# reassembles them once all have arrived. The script prints the carry list of each command.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST="${DEST:-$ROOT/.gpu_wheels}"
PART_MB="${PART_MB:-55}"
PYTHON="${PYTHON:-$ROOT/.venv/bin/python}"
# pdsim's imports on the run paths (pdsim itself is installed from the carried tree with --no-deps, built by
# setuptools); pytest for the agreement tests; warp-lang pinned to the version the tests were written against
PACKAGES="${PACKAGES:-warp-lang==1.19.0 usd-core trimesh tqdm manifold3d meshio pytest pluggy iniconfig packaging setuptools}"

rm -rf "$DEST"
mkdir -p "$DEST/download"
# shellcheck disable=SC2086  # PACKAGES is a list of requirement specifiers
"$PYTHON" -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d "$DEST/download" $PACKAGES
(cd "$DEST/download" && ls -1 ./*.whl > wheels.txt && tar -cf "$DEST/wheels.tar" ./*.whl wheels.txt)
rm -rf "$DEST/download"

bytes=$("$PYTHON" -c "print(int(float('$PART_MB') * 1000 * 1000))")
(cd "$DEST" && split -b "$bytes" -d -a 2 wheels.tar wheels.tar.)
{
    echo "# sha256 of wheels.tar, then of each part (tools/gpu_wheels.sh)"
    (cd "$DEST" && sha256sum wheels.tar)
} > "$DEST/manifest.sha256"
index=0
for part in "$DEST"/wheels.tar.[0-9][0-9]; do
    index=$((index + 1))
    folder=$(printf "part%02d" "$index")
    mkdir -p "$DEST/$folder"
    mv "$part" "$DEST/$folder/"
    (cd "$DEST" && sha256sum "$folder/$(basename "$part")") >> "$DEST/manifest.sha256"
done
rm -f "$DEST/wheels.tar"

echo "wheels packed into $index part(s) under $DEST:"
du -sh "$DEST"/part* | sed 's/^/  /'
rel="${DEST#"$ROOT"/}"
echo "carry, one command per part (the last one runs the suite):"
for folder in "$DEST"/part*; do
    echo "  [\"$rel/manifest.sha256\", \"$rel/$(basename "$folder")\"]"
done
