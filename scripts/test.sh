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
echo "== fuzz/Cargo.lock resolves as committed"
cargo metadata --locked --format-version 1 --manifest-path fuzz/Cargo.toml >/dev/null
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
export RINGSWARM_BIN="$PWD/target/debug/ringswarm"
# Most of these tests wait on real time (flights over UDP, MAVSDK's examples), so they run
# in three groups at once, each in a network namespace of its own: its own loopback, so
# the fixed ports (14540, 14550, …) do not collide. Where namespaces cannot be made (not
# root), the groups run one after the other.
examples=tests/python/test_mavsdk_examples.py
half="mission or velocity_body or takeoff_and_land or offboard_attitude"
group_1=("$examples" -k "$half")
group_2=("$examples" -k "not ($half)")
group_3=(tests/python --ignore="$examples")
pytest_args=(-q -p no:cacheprovider)
if unshare -n true 2>/dev/null; then
  logs=$(mktemp -d)
  pids=()
  for g in 1 2 3; do
    declare -n group="group_$g"
    unshare -n bash -c 'ip link set lo up && exec .venv/bin/python -m pytest "$@"' _ \
      "${pytest_args[@]}" "${group[@]}" >"$logs/$g.log" 2>&1 &
    pids+=($!)
  done
  status=0
  for g in 1 2 3; do
    wait "${pids[$((g - 1))]}" || status=1
    echo "-- python group $g of 3"
    cat "$logs/$g.log"
  done
  rm -rf "$logs"
  exit "$status"
fi
for g in 1 2 3; do
  declare -n group="group_$g"
  .venv/bin/python -m pytest "${pytest_args[@]}" "${group[@]}"
done
