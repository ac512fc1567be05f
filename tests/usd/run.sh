#!/usr/bin/env bash
# Pixar's reader on the USD stage writer: writes the fixture stages with
# examples/usd_fixture.rs and checks them with tests/usd/check_stages.py, and the CLI's
# stages of a sequence against its PLYs with tests/usd/check_run.py, under two
# usd-core releases, each installed once into target/usd-venv-VERSION:
#   25.11: the last with UsdUtils.ComplianceChecker (the check runs it);
#   26.11: the newest, whose crate reader also validates children lists (the check runs
#          its UsdValidation validators instead, which replace the compliance checker).
# MENISCUS_USD_CORE="25.11 26.11" (the default) chooses the releases; MENISCUS_PYTHON the
# interpreter (python3).
set -euo pipefail
cd "$(dirname "$0")/../.."
python="${MENISCUS_PYTHON:-python3}"
out=target/ci/usd
cargo run --release --quiet --example usd_fixture -- "$out" >/dev/null
# The CLI's stages of a 3-frame sequence with a gap (frames 1, 2, 4), spheres on and off,
# both formats, and the PLYs of the same runs, for tests/usd/check_run.py.
pattern=$(cargo run --release --quiet --example particle_sequence -- "$out/particles")
for spheres in 2 off; do
  for output in "$out/run-$spheres.usdc" "$out/run-$spheres.usda" "$out/run-$spheres-{}.ply"; do
    cargo run --release --quiet -- reconstruct "$pattern" --particle-radius 0.025 \
      --attributes all --isolated-spheres "$spheres" -o "$output" --quiet
  done
done
# The droplets as a point instancer (the default is a point cloud).
cargo run --release --quiet -- reconstruct "$pattern" --particle-radius 0.025 \
  --attributes all --isolated-spheres 2 --usd-droplets instancer -o "$out/run-inst.usdc" --quiet
for version in ${MENISCUS_USD_CORE:-25.11 26.11}; do
  venv="target/usd-venv-$version"
  if ! "$venv/bin/python" -c "import pxr.Usd" >/dev/null 2>&1; then
    rm -rf "$venv"
    "$python" -m venv "$venv"
    "$venv/bin/pip" install --quiet --disable-pip-version-check "usd-core==$version"
  fi
  "$venv/bin/python" tests/usd/check_stages.py "$out"
  for spheres in 2 off; do
    for stage in "$out/run-$spheres.usdc" "$out/run-$spheres.usda"; do
      "$venv/bin/python" tests/usd/check_run.py "$stage" "$out/run-$spheres-{}.ply" 1 2 4
    done
  done
  "$venv/bin/python" tests/usd/check_run.py "$out/run-inst.usdc" "$out/run-2-{}.ply" 1 2 4
done
