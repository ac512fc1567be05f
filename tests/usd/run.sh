#!/usr/bin/env bash
# Pixar's reader on the USD stage writer: writes the fixture stages with
# examples/usd_fixture.rs and checks them with tests/usd/check_stages.py under two
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
for version in ${MENISCUS_USD_CORE:-25.11 26.11}; do
  venv="target/usd-venv-$version"
  if ! "$venv/bin/python" -c "import pxr.Usd" >/dev/null 2>&1; then
    rm -rf "$venv"
    "$python" -m venv "$venv"
    "$venv/bin/pip" install --quiet --disable-pip-version-check "usd-core==$version"
  fi
  "$venv/bin/python" tests/usd/check_stages.py "$out"
done
