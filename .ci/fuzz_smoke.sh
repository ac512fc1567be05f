#!/usr/bin/env bash
# A short cargo-fuzz run (FUZZ_SECONDS, default 30, per target) of the targets whose
# readers changed: src/archive → archive targets, src/io/particles → particle targets,
# src/io/mesh (or the rest of src/io) → mesh targets, src/sequence or the VTK XML
# scanner under src/io/particles/vtk_xml (which reads the .pvd markup) → sequence_pvd,
# anything under src → reconstruct (the whole pipeline on small random particle sets with
# random radii and attributes; each input runs in milliseconds, 30 s in all).
# Changes are taken against FUZZ_BASE (default: origin/main, else main, else the
# previous commit); with FUZZ_ALL=1 every target runs. Stable toolchain with
# RUSTC_BOOTSTRAP=1, as fuzz/README.md explains; cargo-fuzz is installed when missing.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${FUZZ_SECONDS:-30}
base=${FUZZ_BASE:-}
if [ -z "$base" ]; then
  for candidate in origin/main main HEAD~1; do
    if git rev-parse --verify -q "$candidate" >/dev/null; then base=$candidate; break; fi
  done
fi
# Since the branch left the base (its merge base), committed or not.
since=$(git merge-base "$base" HEAD)
changed=$( { git diff --name-only "$since" -- src; git status --porcelain -- src | cut -c4-; } | sort -u)
targets=()
if [ "${FUZZ_ALL:-0}" = 1 ] || grep -q '^src/archive/' <<<"$changed"; then
  targets+=(archive archive_payload)
fi
if [ "${FUZZ_ALL:-0}" = 1 ] || grep -q '^src/io/particles' <<<"$changed"; then
  targets+=(particles_xyz particles_ply particles_bgeo particles_vtk particles_vtk_xml)
fi
if [ "${FUZZ_ALL:-0}" = 1 ] || grep -Eq '^src/io/(mesh|[^/]*\.rs)' <<<"$changed"; then
  targets+=(mesh_ply mesh_obj mesh_gltf mesh_vtk)
fi
if [ "${FUZZ_ALL:-0}" = 1 ] || grep -Eq '^src/(sequence/|io/particles/vtk_xml/)' <<<"$changed"; then
  targets+=(sequence_pvd)
fi
if [ "${FUZZ_ALL:-0}" = 1 ] || grep -q '^src/' <<<"$changed"; then
  targets+=(reconstruct)
fi
if [ ${#targets[@]} -eq 0 ]; then
  echo "no change to src since $base (${since:0:8}): no fuzzing"
  exit 0
fi
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
for t in "${targets[@]}"; do
  mkdir -p "fuzz/corpus/$t"
  echo "== fuzz $t (${seconds} s)"
  RUSTC_BOOTSTRAP=1 cargo fuzz run "$t" "fuzz/corpus/$t" "fuzz/seeds/$t" -- \
    -max_total_time="$seconds" -rss_limit_mb=2048 -timeout=10 2>&1 | tail -25
done
