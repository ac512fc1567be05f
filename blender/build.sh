#!/usr/bin/env bash
# Builds the Blender extension zip: the meniscus Python wheel (maturin, for the Python of
# Blender, 3.11: the wheel is abi3, cp310 and up) bundled with the add-on's files and its
# blender_manifest.toml listing the wheel. Prints the zip's path.
#   bash blender/build.sh [OUT_DIR]       (default target/blender)
# Install it in Blender: Edit ▸ Preferences ▸ Get Extensions ▸ Install from Disk.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-target/blender}"
python="${MENISCUS_PYTHON:-python3.11}"
venv=target/maturin-venv
if ! "$venv/bin/maturin" --version >/dev/null 2>&1; then
  rm -rf "$venv"
  "$python" -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check "maturin>=1.5,<2"
fi
rm -rf "$out/wheels"
mkdir -p "$out/wheels"
"$venv/bin/maturin" build --quiet --release -m python/Cargo.toml -i "$python" --out "$out/wheels" >&2
"$python" - "$out" <<'PY'
import pathlib, re, sys, zipfile
out = pathlib.Path(sys.argv[1])
wheels = sorted((out / "wheels").glob("meniscus-*.whl"))
assert len(wheels) == 1, wheels
wheel = wheels[0]
source = pathlib.Path("blender/meniscus_blender")
manifest = (source / "blender_manifest.toml").read_text()
manifest = re.sub(r"(?m)^wheels = \[\]$", f'wheels = ["./wheels/{wheel.name}"]', manifest)
version = re.search(r'(?m)^version = "([^"]+)"', manifest).group(1)
zip_path = out / f"meniscus-blender-{version}.zip"
with zipfile.ZipFile(zip_path, "w", zipfile.ZIP_DEFLATED) as z:
    z.writestr("blender_manifest.toml", manifest)
    for f in sorted(source.glob("*.py")):
        z.write(f, f.name)
    z.write(wheel, f"wheels/{wheel.name}")
print(zip_path)
PY
