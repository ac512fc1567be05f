#!/usr/bin/env bash
# The Python package: build it into a fresh venv and run its tests (which compare its
# output with the CLI's, built by cargo in the same target directory).
set -euo pipefail
cd "$(dirname "$0")/.."
venv="${CARGO_TARGET_DIR:-target}/ci/pyvenv"
rm -rf "$venv"
python3 -m venv "$venv"
# shellcheck disable=SC1091
. "$venv/bin/activate"
pip install -q --upgrade pip
pip install -q maturin pytest numpy "dask[distributed]" "usd-core==26.11"
cargo clippy --release -p meniscus-python --all-targets -- -D warnings
# The package's own Rust unit tests (its edge numbering); not among the default members.
cargo test --release --quiet -p meniscus-python --lib
(cd python && maturin develop --release)
cargo build --release --quiet --bin meniscus
pytest python/tests -q
