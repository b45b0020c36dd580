#!/usr/bin/env bash
# Runs every test of the project on a fresh machine:
#   formatting, clippy (warnings are errors), all Rust tests (unit, integration, doc),
#   then the Python checks against independent numpy computations, pymavlink, MAVSDK and
#   headless Chromium (Debian's, installed when missing), in a project-local virtual
#   environment (.venv) with pinned packages.
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step's heading carries the time it starts (UTC), for the CI log.
step() { echo "== [$(date -u +%H:%M:%S)] $*"; }

# What the Python checks need (Debian's chromium, the venv's packages) downloads and
# installs while Rust compiles: it waits on the network and the disk, the build on the
# two cores. Its output goes to a log, shown if it fails.
setup_log="$(mktemp)"
python_setup() {
  set -e
  if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then
    echo "== browser for the live view's tests: Debian's chromium and its chromedriver"
    sudo=""
    if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
    $sudo apt-get update -q
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends chromium chromium-driver
  fi
  if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
  fi
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt
  # MAVProxy headless, without its GUI's dependencies (matplotlib, OpenCV, VTK: hundreds of
  # megabytes that a console on stdin never imports).
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps MAVProxy==1.8.75
}
python_setup >"$setup_log" 2>&1 &
setup_pid=$!

step "cargo fmt --check"
cargo fmt --all --check

step "import circles between modules"
python3 scripts/import_circles.py

# Clippy runs as the workspace crates' compiler inside the builds below
# (RUSTC_WORKSPACE_WRAPPER, as `cargo clippy` does for `cargo check`), its lints errors
# (CLIPPY_ARGS, in the form `cargo clippy` hands them over). The dependencies are then
# compiled once, for the tests, where `cargo clippy` first checked them all and the test
# build compiled them again: about 5 min of a CI run. A probe first shows that a lint is
# denied this way, so that a change in that hand-over cannot pass unlinted code.
step "clippy as the workspace's compiler: a probe"
export RUSTC_WORKSPACE_WRAPPER=clippy-driver
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
probe="$(mktemp -d)"
printf 'pub fn probe(v: &[u8]) -> bool {\n    v.len() == 0\n}\n' >"$probe/probe.rs"
if clippy-driver rustc --edition 2024 --crate-type lib --emit=metadata \
  -o "$probe/probe.rmeta" "$probe/probe.rs" >/dev/null 2>&1; then
  echo "clippy-driver did not deny a lint handed over in CLIPPY_ARGS: the builds below would not be linted"
  exit 1
fi
step "cargo test --no-run --all-targets (linted)"
cargo test --workspace --locked --no-run --all-targets
# The flight coordinator alone, without the emulator, as a companion computer builds it
# (with Zenoh, for its shard). Without Zenoh as well, Cargo unifies the dependencies'
# features further from the workspace's and builds many of them again. What that leaves
# out is two five-line fallbacks that refuse `--shard` and `view --zenoh`. Checked, not
# built: type and borrow checking and the lints are what differ between feature sets, and
# a check skips the code generation of every dependency built again (measured from a cold
# cache: 2 min 26 s against 4 min 1 s for the build).
step "cargo check, the coordinator without the emulator (linted)"
cargo check --no-default-features --features zenoh --lib --bins --locked
step "fuzz/Cargo.lock resolves as committed"
cargo metadata --locked --format-version 1 --manifest-path fuzz/Cargo.toml >/dev/null
step "cargo test"
cargo test --workspace --locked
step "cargo build --bins"
cargo build --workspace --locked --bins

step "python checks: chromium and the venv (set up during the build)"
if ! wait "$setup_pid"; then
  cat "$setup_log"
  echo "the Python checks' setup failed (above)"
  exit 1
fi
cat "$setup_log"
# The binary the Python checks run: where Cargo put it (CARGO_TARGET_DIR, when a build
# cache is kept outside the clone).
export RINGSWARM_BIN="$(realpath -m "${CARGO_TARGET_DIR:-target}")/debug/ringswarm"
# Most of these tests wait on real time (flights over UDP, MAVSDK's examples), so they run
# in parallel, on pytest-xdist's workers. They use PX4's fixed ports (14540, 14550, …), so
# each worker takes a network namespace of its own with its own loopback
# (tests/python/conftest.py). Where namespaces cannot be made (not root), they run in one
# process, one after the other.
pytest_args=(-q -p no:cacheprovider --durations=8 tests/python)
# The flights below run in real time: let the build's gigabytes reach the disk first, so
# that their writeback does not slow the flights down.
sync
# The tests marked serial (several shards, emulators and coordinators in real time each)
# run afterwards, alone, so that neither they nor the others fly on a loaded machine.
if unshare -n true 2>/dev/null; then
  step "python checks in parallel"
  RINGSWARM_TEST_NETNS=1 .venv/bin/python -m pytest "${pytest_args[@]}" -m "not serial" -n "${RINGSWARM_PYTEST_WORKERS:-4}" --dist loadgroup
  step "python checks marked serial, alone"
  unshare -n bash -c 'ip link set lo up && exec .venv/bin/python -m pytest "$@"' _ "${pytest_args[@]}" -m serial -n 0
else
  echo "python checks: network namespaces cannot be made here (unshare -n), so they run one at a time"
  .venv/bin/python -m pytest "${pytest_args[@]}" -n 0
fi
step "done"
