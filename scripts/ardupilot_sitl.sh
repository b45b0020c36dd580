#!/usr/bin/env bash
# Starts N real ArduCopter SITL instances (its built-in quad physics, headless) for
# ringswarm, runs COMMAND, then stops them. Build ArduCopter first with
# ../shared/ardupilot-sitl/build.sh (it gives ARDUPILOT/build/sitl/bin/arducopter).
#
#   scripts/ardupilot_sitl.sh ARDUPILOT N [FIRST] -- COMMAND...
#
# Instance i (0-based, from FIRST, default 0): system id FIRST+i+1, its own working directory
# (eeprom.bin, logs) wiped at start, home 5 m east of the one before it from
# 47.397742, 8.545594 (488 m AMSL), and SERIAL0 a UDP client of 127.0.0.1:14540+FIRST+i,
# the socket `ringswarm fly` binds for vehicle FIRST+i: the coordinator answers where its
# frames come from. Each instance's output is in WORKDIR/ap_<sysid>.log, WORKDIR being
# $AP_SITL_WORKDIR or a fresh temporary folder. Run it inside a network namespace of its
# own when other things use those ports:
#   unshare -n bash -c 'ip link set lo up; scripts/ardupilot_sitl.sh A 6 -- ringswarm fly --config F'
set -u
AP=${1:?ArduPilot source folder (with build/sitl/bin/arducopter)}; N=${2:?instances}
shift 2
FIRST=0
if [ $# -gt 0 ] && [ "$1" != "--" ]; then FIRST=$1; shift; fi
[ "${1:-}" = "--" ] && shift
BIN=$AP/build/sitl/bin/arducopter
DEFAULTS=$AP/Tools/autotest/default_params/copter.parm
[ -x "$BIN" ] || { echo "no $BIN: build it with ../shared/ardupilot-sitl/build.sh" >&2; exit 2; }
WORK=${AP_SITL_WORKDIR:-$(mktemp -d)}
pids=()
for k in $(seq 0 $((N-1))); do
  i=$((FIRST+k)); sysid=$((i+1))
  dir="$WORK/ap_$sysid"; rm -rf "$dir"; mkdir -p "$dir"
  lon=$(python3 -c "import math; print(8.545594 + 5.0*$i/(111319.49*math.cos(math.radians(47.397742))))")
  ( cd "$dir" && exec "$BIN" --model quad --speedup 1 --defaults "$DEFAULTS" -I "$i" -w \
      --sysid "$sysid" --serial0 "udpclient:127.0.0.1:$((14540+i))" \
      --home "47.397742,$lon,488,0" > "$WORK/ap_$sysid.log" 2>&1 < /dev/null ) &
  pids+=($!)
done
stop() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done; sleep 1; for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done; }
trap stop EXIT INT TERM
echo "ArduCopter SITL: $N instances from $((FIRST+1)), logs in $WORK" >&2
if [ $# -gt 0 ]; then "$@"; else wait; fi
