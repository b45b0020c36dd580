"""Two `ringswarm fly --shard` processes flying `ringswarm sitl` vehicles over real UDP,
talking to each other over Zenoh on the loopback (tests/fixtures/ground-diamond-shards.toml:
the ground diamond of test_fly.py, one macro-vertex per shard).

What is checked, from each shard's run directory:
- both adopt one consensus start, the same instant on the swarm clock (Unix µs), and
  both predict the same final velocity: every vehicle starts at rest, so (0, 0);
- both fly their own vehicles to the end and land them (exit code 0);
- a shard killed in flight makes the other apply its loss policy (hold);
- `ringswarm view --zenoh` (flying nothing) shows the whole swarm from the shards'
  traffic: every vehicle, the phase, the prediction, the formation closing, and a
  killed shard falling silent.
"""

import json
import os
import socket
import subprocess
import urllib.request
from pathlib import Path

import pytest
from shard_runs import PREDICTED, START, events, stop, wait_for

pytestmark = pytest.mark.serial

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
CONFIG = ROOT / "tests" / "fixtures" / "ground-diamond-shards.toml"


def start(tmp, extra=()):
    log = open(tmp / "sitl.log", "w")
    sitl = subprocess.Popen([BIN, "sitl", "--config", str(CONFIG)], stdout=log, stderr=subprocess.STDOUT)
    shards = {}
    for name in ("a", "b"):
        out = tmp / f"run-{name}"
        shard_log = open(tmp / f"{name}.log", "w")
        shards[name] = (
            subprocess.Popen(
                [BIN, "fly", "--config", str(CONFIG), "--shard", name, "--out", str(out), *extra],
                stdout=shard_log,
                stderr=subprocess.STDOUT,
            ),
            out,
        )
    return sitl, shards


def test_two_shards_adopt_one_start_and_one_prediction_and_land(tmp_path):
    sitl, shards = start(tmp_path)
    try:
        for name, (process, _) in shards.items():
            rc = process.wait(timeout=150)
            assert rc == 0, (tmp_path / f"{name}.log").read_text()[-3000:]
    finally:
        for process, _ in shards.values():
            stop(process)
        stop(sitl)
    starts, predictions = {}, {}
    for name, (_, out) in shards.items():
        text = [row[-1] for row in events(out)]
        found = [START.search(t) for t in text]
        found = [m for m in found if m]
        assert len(found) == 1, text
        starts[name] = int(found[0].group(2))
        predicted = [PREDICTED.search(t) for t in text if "every shard's sum" in t]
        assert len(predicted) == 1, text
        predictions[name] = (float(predicted[0].group(1)), float(predicted[0].group(2)))
        assert not any("is lost" in t for t in text), text
    assert starts["a"] == starts["b"], starts
    assert predictions["a"] == predictions["b"] == (0.0, 0.0), predictions


def test_a_killed_shard_makes_the_other_hold(tmp_path):
    sitl, shards = start(tmp_path, ("--duration-s", "60"))
    try:
        for _, out in shards.values():
            wait_for(lambda out=out: any(START.search(r[-1]) for r in events(out)), 60, f"consensus in {out}")
        process, _ = shards["b"]
        process.kill()
        _, out_a = shards["a"]
        row = wait_for(
            lambda: next((r for r in events(out_a) if "a vehicle is lost" in r[-1]), None),
            15,
            "shard a applying its loss policy",
        )
        assert "brake and hold" in row[-1], row
        # Its cause: shard b's vehicles' states gone stale (300 ms), or its reports silent
        # (1.5 s), whichever came first; the timing itself is pinned in virtual time
        # (tests/integration/lockstep_shards.rs).
        assert "a vehicle is lost" in row[-1] and row[1] == "", row
        start_row = next(r for r in events(out_a) if START.search(r[-1]))
        assert float(row[0]) > float(start_row[0])
    finally:
        for process, _ in shards.values():
            stop(process)
        stop(sitl)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_view_zenoh_shows_the_whole_swarm_from_the_shards_traffic(tmp_path):
    port = free_port()
    log = open(tmp_path / "view.log", "w")
    view = subprocess.Popen(
        [BIN, "view", "--config", str(CONFIG), "--zenoh", "tcp/127.0.0.1:7447",
         "--zenoh", "tcp/127.0.0.1:7448", "--web", f"127.0.0.1:{port}"],
        stdout=log, stderr=subprocess.STDOUT)
    sitl, shards = start(tmp_path, ("--duration-s", "30"))

    def state():
        try:
            return json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/api/state", timeout=5).read())
        except OSError:
            return None

    try:
        flying = wait_for(
            lambda: (st := state()) and st["phase"] == "consensus"
            and all(v["position_enu_m"] for v in st["vehicles"]) and st,
            60, "the viewer showing the swarm in consensus")
        assert [v["sysid"] for v in flying["vehicles"]] == [1, 2, 3, 4]
        assert all(v["link_phase"] == "flying" for v in flying["vehicles"]), flying["vehicles"]
        # Every vehicle starts at rest: the shards' start sums predict (0, 0).
        assert flying["predicted_final_velocity"] == [0.0, 0.0]
        assert any("adopts the start" in e["text"] for e in flying["events"])
        # The diamond closes (the shards' own runs measure 7 cm at the end).
        wait_for(lambda: (st := state()) and st["formation_error_m"] is not None
                 and st["formation_error_m"] < 0.5, 40, "the formation closing in the viewer")
        shards["b"][0].kill()
        wait_for(lambda: (st := state()) and any('shard "b" silent' in e["text"] for e in st["events"]),
                 15, "the viewer saying shard b fell silent")
    finally:
        for process, _ in shards.values():
            stop(process)
        stop(sitl)
        stop(view)
    assert "watching swarm" in (tmp_path / "view.log").read_text()
