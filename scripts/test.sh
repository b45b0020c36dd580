#!/usr/bin/env bash
# Runs every test of the project on a fresh machine:
#   formatting, clippy (warnings are errors), all Rust tests (unit, integration, doc),
#   then the Python checks against independent numpy computations, in a project-local
#   virtual environment (.venv) with pinned packages.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== cargo fmt --check"
cargo fmt --all --check
echo "== cargo clippy"
cargo clippy --workspace --all-targets --locked -- -D warnings
# The flight coordinator alone, without the emulator.
cargo clippy --no-default-features --lib --bins --locked -- -D warnings
echo "== cargo test"
cargo test --workspace --locked
cargo build --workspace --locked --bins

echo "== python checks"
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt
RINGSWARM_BIN="$PWD/target/debug/ringswarm" .venv/bin/python -m pytest -q tests/python
