#!/usr/bin/env bash
# Packs what pdsim needs on a GPU machine that has Python 3.12 with numpy, scipy, tqdm and pytest but no registry
# (tools/gpu_suite.sh runs there): the wheels below in one tar (about 185 MB, Warp's wheel 150 MB of it; the wheels
# are compressed already: xz gains a third of a part and takes minutes), split into parts under PART_MB (default 48:
# the files sent with one command are limited to 64 MiB, the working tree included), each part in a folder of its own
# under .gpu_wheels/ (ignored by git), with a manifest (SHA-256 of the archive and of each part). gpu_suite.sh unpacks
# the wheels into one site folder on the GPU machine.
#
#   bash tools/gpu_wheels.sh                 # the packages of the GPU suite, parts of 48 MB
#   PACKAGES="tqdm" PART_MB=0.03 DEST=/tmp/w bash tools/gpu_wheels.sh   # a small trial (the split and the manifest)
#
# Each command on the GPU machine carries the manifest and one part (carry: .gpu_wheels/manifest.sha256 and
# .gpu_wheels/part01, ...); the parts stay on the machine between its commands while it is held, and gpu_suite.sh
# reassembles them once all have arrived. The script prints the carry list of each command.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST="${DEST:-$ROOT/.gpu_wheels}"
PART_MB="${PART_MB:-48}"
PYTHON="${PYTHON:-$ROOT/.venv/bin/python}"
# pdsim's imports on the run paths that the GPU machine lacks (pdsim itself is installed from the carried tree with
# --no-deps; rtree for the tests' trimesh proximity queries); warp-lang pinned to the version the tests were written against
PACKAGES="${PACKAGES:-warp-lang==1.19.0 usd-core trimesh manifold3d meshio pytetwild rtree}"

rm -rf "$DEST"
mkdir -p "$DEST/download"
# shellcheck disable=SC2086  # PACKAGES is a list of requirement specifiers
"$PYTHON" -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
    --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_17_x86_64 \
    --platform manylinux2014_x86_64 -d "$DEST/download" $PACKAGES
(cd "$DEST/download" && ls -1 ./*.whl > wheels.txt && tar -cf "$DEST/site.tar" ./*.whl wheels.txt)
rm -rf "$DEST/download"

bytes=$("$PYTHON" -c "print(int(float('$PART_MB') * 1000 * 1000))")
(cd "$DEST" && split -b "$bytes" -d -a 2 site.tar site.tar.)
{
    echo "# sha256 of site.tar, then of each part (tools/gpu_wheels.sh)"
    (cd "$DEST" && sha256sum site.tar)
} > "$DEST/manifest.sha256"
index=0
for part in "$DEST"/site.tar.[0-9][0-9]; do
    index=$((index + 1))
    folder=$(printf "part%02d" "$index")
    mkdir -p "$DEST/$folder"
    mv "$part" "$DEST/$folder/"
    (cd "$DEST" && sha256sum "$folder/$(basename "$part")") >> "$DEST/manifest.sha256"
done
rm -f "$DEST/site.tar"

echo "packed into $index part(s) under $DEST:"
du -sh "$DEST"/part* | sed 's/^/  /'
rel="${DEST#"$ROOT"/}"
echo "carry, one command per part (the last one runs the suite):"
for folder in "$DEST"/part*; do
    echo "  [\"$rel/manifest.sha256\", \"$rel/$(basename "$folder")\"]"
done
