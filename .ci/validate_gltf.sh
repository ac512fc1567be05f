#!/usr/bin/env bash
# Installs the Khronos glTF-Validator (npm package gltf-validator) into a cache folder if
# it is missing, then validates the given files. Usage: validate_gltf.sh FILE...
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cache="${GLTF_VALIDATOR_CACHE:-$here/../target/gltf-validator}"
if [ ! -d "$cache/node_modules/gltf-validator" ]; then
  command -v npm >/dev/null || { echo "npm is needed for the glTF validator" >&2; exit 1; }
  mkdir -p "$cache"
  (cd "$cache" && npm install --silent --no-audit --no-fund gltf-validator >/dev/null)
fi
GLTF_VALIDATOR_DIR="$cache" node "$here/validate_gltf.mjs" "$@"
