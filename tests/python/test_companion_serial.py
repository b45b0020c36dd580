"""Companion mode: a shard on each vehicle's own computer, a serial cable to its
autopilot. `ringswarm sitl` serves vehicles 1 and 2 of the ground diamond on
pseudo-terminals linked at the configured device paths (as a flight controller's TELEM
port), and 3 and 4 on PX4's UDP ports. Three `fly --shard` processes fly them: "v1" and
"v2" over their serial lines, "ground" over UDP, and the three talk over Zenoh.

What is checked, from each shard's run directory:
- every shard adopts one consensus start (one instant on the swarm clock) and one
  prediction, (0, 0) m/s: every vehicle starts at rest;
- the companion shards' traffic (their .tlog) is their own vehicle's only: its
  heartbeats, and setpoints to it at the control rate;
- the formation closes and every shard lands its vehicles (exit code 0).
"""

import json
import os
import subprocess
from pathlib import Path

import pytest
from shard_runs import events, predictions_of, starts_of, stop, wait_for
from tlog import read_tlog

pytestmark = pytest.mark.serial

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
DIAMOND = ROOT / "tests" / "fixtures" / "ground-diamond-shards.toml"
RATE_HZ = 50.0


def companion_config(tmp):
    """The ground diamond with vehicles 1 and 2 on serial ports, in three shards."""
    text = DIAMOND.read_text()
    text = text[: text.index("# Split in two shards")]
    for sysid in (1, 2):
        device = tmp / f"tty-v{sysid}"
        text = text.replace(
            f"system_id = {sysid}\n",
            f'system_id = {sysid}\nserial = {{ device = "{device}", baud = 921600 }}\n',
            1,
        )
    text += """
[distributed]
swarm = "companion"

[[shard]]
name = "ground"
vehicles = [{ system_id = 3 }, { system_id = 4 }]
listen = ["tcp/127.0.0.1:7449"]

[[shard]]
name = "v1"
vehicles = [{ system_id = 1 }]
listen = ["tcp/127.0.0.1:7450"]
connect = ["tcp/127.0.0.1:7449"]

[[shard]]
name = "v2"
vehicles = [{ system_id = 2 }]
connect = ["tcp/127.0.0.1:7449", "tcp/127.0.0.1:7450"]
"""
    path = tmp / "companion.toml"
    path.write_text(text)
    return path


def test_companion_shards_fly_their_vehicles_over_serial_lines(tmp_path):
    config = companion_config(tmp_path)
    sitl_log = open(tmp_path / "sitl.log", "w")
    sitl = subprocess.Popen([BIN, "sitl", "--config", str(config)], stdout=sitl_log, stderr=subprocess.STDOUT)
    shards = {}
    try:
        # The emulator links each device path to its pseudo-terminal once it serves it.
        for sysid in (1, 2):
            device = tmp_path / f"tty-v{sysid}"
            wait_for(lambda d=device: d.is_symlink() and os.readlink(d).startswith("/dev/pts/"), 30,
                     f"the emulator serving vehicle {sysid} at {device}")
        for name in ("ground", "v1", "v2"):
            log = open(tmp_path / f"{name}.log", "w")
            out = tmp_path / f"run-{name}"
            process = subprocess.Popen(
                [BIN, "fly", "--config", str(config), "--shard", name, "--out", str(out)],
                stdout=log, stderr=subprocess.STDOUT)
            shards[name] = (process, out)
        for name, (process, _) in shards.items():
            rc = process.wait(timeout=150)
            assert rc == 0, (tmp_path / f"{name}.log").read_text()[-3000:]
    finally:
        for process, _ in shards.values():
            stop(process)
        stop(sitl)
    starts = {name: starts_of(out) for name, (_, out) in shards.items()}
    assert all(len(s) == 1 for s in starts.values()), starts
    assert len({s[0][1] for s in starts.values()}) == 1, starts
    predictions = {name: predictions_of(out) for name, (_, out) in shards.items()}
    assert all(p == [(0.0, 0.0)] for p in predictions.values()), predictions
    for name, (_, out) in shards.items():
        text = [row[-1] for row in events(out)]
        assert not any("is lost" in t for t in text), (name, text)
        summary = json.loads((out / "summary.json").read_text())
        assert summary["failure"] is None, (name, summary["failure"])
        assert summary["formation_error_m"] < 0.25, (name, summary["formation_error_m"])
    # Over each serial line: only that vehicle's frames, and its setpoints at the rate.
    for sysid in (1, 2):
        messages = read_tlog(shards[f"v{sysid}"][1] / "traffic.tlog")
        vehicles_heard = {m.get_srcSystem() for m in messages if m.get_type() == "HEARTBEAT"
                          and m.get_srcComponent() == 1}
        assert vehicles_heard == {sysid}, vehicles_heard
        stamps = [m._timestamp for m in messages
                  if m.get_type() == "SET_ATTITUDE_TARGET" and m.target_system == sysid]
        assert len(stamps) > 200
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        assert abs(rate - RATE_HZ) < 0.05 * RATE_HZ, (sysid, rate)
        assert not [m for m in messages if m.get_type() == "SET_ATTITUDE_TARGET" and m.target_system != sysid]
