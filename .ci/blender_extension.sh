#!/usr/bin/env bash
# The Blender extension with the real client: builds its zip (blender/build.sh), installs
# it into bpy 5.0.1 (target/bpy-venv, as .ci/blender_check.sh makes it) in a user
# directory of its own, bakes three shipped dam-break frames through its operator and
# plays them back against the CLI's output of the same frames, meshes them live on frame
# change against the CLI's output with the same presets, then a sequence with velocity
# for motion blur (tests/blender/extension_check.py says what is checked).
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/bpy-venv
python="${MENISCUS_PYTHON:-python3.11}"
if ! "$venv/bin/python" -c "import bpy" >/dev/null 2>&1; then
  rm -rf "$venv"
  "$python" -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check bpy==5.0.1
fi
zip=$(bash blender/build.sh)
work=target/ci/blender-extension
rm -rf "$work"
mkdir -p "$work/dam"
for k in 1 9 17; do
  cp "datasets/dambreak_small/ParticleData_Fluid_$k.xyz" "$work/dam/f_$k.xyz"
done
for output in "$work/cli.mseq" "$work/cli_{}.ply"; do
  cargo run --release --quiet -- reconstruct "$work/dam/f_{}.xyz" -o "$output" --quiet
done
# The live route's viewport preset (the extension's Preview: the still preset, h = 2 r,
# no decimation or subdivision, one smoothing step); its render preset is the steady
# default above.
cargo run --release --quiet -- reconstruct "$work/dam/f_{}.xyz" -o "$work/cli_preview_{}.ply" --quiet \
  --preset still --cell-size 2 --decimate off --subdivide 0 --smooth 1
velocity=$(cargo run --release --quiet --example particle_sequence -- "$work/velocity")
BLENDER_USER_RESOURCES="$PWD/$work/user" "$venv/bin/python" tests/blender/extension_check.py \
  "$zip" "$work" "$work/dam/f_{}.xyz" "$velocity"
