#!/usr/bin/env bash
# Runs every test of the project on a fresh machine:
#   formatting, clippy (warnings are errors), all Rust tests (unit, integration, doc),
#   then the Python checks against independent numpy computations, pymavlink, MAVSDK and
#   headless Chromium (Debian's, installed when missing), in a project-local virtual
#   environment (.venv) with pinned packages.
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

echo "== browser for the live view's tests: Debian's chromium and its chromedriver"
if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends chromium chromium-driver
fi

echo "== python checks"
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt
RINGSWARM_BIN="$PWD/target/debug/ringswarm" .venv/bin/python -m pytest -q tests/python
