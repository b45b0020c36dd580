#!/usr/bin/env bash
# Runs every libFuzzer target for SECONDS each (default 60) with cargo-fuzz on nightly,
# starting from the committed seeds in fuzz/corpus/<target>; new inputs go to
# target/fuzz-corpus/<target>, crashes to fuzz/artifacts/<target>. Prints a table.
#   scripts/fuzz.sh [SECONDS]
# Needs: rustup toolchain nightly, cargo install cargo-fuzz.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-60}"
if ! [[ "$seconds" =~ ^[0-9]+$ ]] || [ "$seconds" -eq 0 ]; then
  echo "usage: scripts/fuzz.sh [SECONDS]  (a whole number of seconds per target, got '$seconds')" >&2
  exit 2
fi
targets=(decode emulator_inbound coordinator_inbound coordinator_config sitl_config)
cargo +nightly fuzz build --fuzz-dir fuzz
printf '%-22s %8s %12s %10s %8s %s\n' target seconds executions "exec/s" corpus result
status=0
for t in "${targets[@]}"; do
  work="target/fuzz-corpus/$t"
  mkdir -p "$work"
  log="target/fuzz-corpus/$t.log"
  if cargo +nightly fuzz run --fuzz-dir fuzz "$t" "$work" "fuzz/corpus/$t" -- \
      -max_total_time="$seconds" -rss_limit_mb=2048 -print_final_stats=1 >"$log" 2>&1; then
    result=clean
  else
    result="CRASH (see $log, fuzz/artifacts/$t)"
    status=1
  fi
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
  rate=$(grep -o 'stat::average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$' | tail -1)
  corpus=$(find "$work" -type f | wc -l)
  printf '%-22s %8s %12s %10s %8s %s\n' "$t" "$seconds" "${runs:-?}" "${rate:-?}" "$corpus" "$result"
done
exit $status
