#!/usr/bin/env bash
# Checks that Blender 5 imports meniscus attributes and USD stages: installs bpy 5.0.1
# (Blender as a Python module) into target/bpy-venv if missing, writes the attribute
# fixtures with the attribute_fixture example and runs tests/blender/import_attributes.py
# on them, then imports a reconstruction (glTF) and a USD stage of a sequence
# (tests/blender/import_usd.py). Exits non-zero when an import loses or changes a value.
set -euo pipefail
cd "$(dirname "$0")/.."
venv=target/bpy-venv
python="${MENISCUS_PYTHON:-python3.11}"
if ! "$venv/bin/python" -c "import bpy" >/dev/null 2>&1; then
  command -v "$python" >/dev/null || { echo "$python is needed for the Blender check (bpy 5.0.1 wheels are for CPython 3.11)" >&2; exit 1; }
  rm -rf "$venv"
  "$python" -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check bpy==5.0.1
fi
out=target/ci/blender
cargo run --release --quiet --example attribute_fixture -- "$out" >/dev/null
# Blender 5.0.1's glTF importer pairs custom attributes with their data through a Python
# set, whose order follows the hash seed: with two or more custom attributes the import
# fails for some seeds (KhronosGroup/glTF-Blender-IO#2658, fixed by #2665, not in 5.0.1).
# A seed under which it works keeps this check about our files, not about that bug.
PYTHONHASHSEED=2 "$venv/bin/python" tests/blender/import_attributes.py "$out"
# A real reconstruction with velocity (the CLI's default for this VTK frame), as a user
# would import it for motion blur.
cargo run --release --quiet -- reconstruct datasets/dambreak_small/ParticleData_Fluid_25.vtk \
  --particle-radius 0.012 -o "$out/frame25.glb" --quiet
cargo run --release --quiet -- reconstruct datasets/dambreak_small/ParticleData_Fluid_25.vtk \
  --particle-radius 0.012 -o "$out/frame25.ply" --quiet
PYTHONHASHSEED=2 "$venv/bin/python" tests/blender/import_reconstruction.py "$out/frame25.glb" "$out/frame25.ply"
# A USD stage of a 3-frame sequence with a gap (frames 1, 2, 4; velocity mostly +Y),
# against the PLYs of the same run: Mesh Sequence Cache, frame range, faces and velocity
# at the middle frame, the velocity turned to Blender's +Z, a Cycles motion-blur render.
pattern=$(cargo run --release --quiet --example particle_sequence -- "$out/particles")
for output in "$out/shot.usdc" "$out/f_{}.ply"; do
  cargo run --release --quiet -- reconstruct "$pattern" --particle-radius 0.025 \
    --isolated-spheres off -o "$output" --quiet
done
"$venv/bin/python" tests/blender/import_usd.py "$out/shot.usdc" "$out/f_{}.ply"
# The same sequence with its isolated particles (the default): the droplets arrive as a
# point cloud with `velocity` and `radius`, and motion blur changes their pixels.
cargo run --release --quiet -- reconstruct "$pattern" --particle-radius 0.025 \
  -o "$out/droplets.usdc" --quiet
"$venv/bin/python" tests/blender/import_droplets.py "$out/droplets.usdc" 0.025
