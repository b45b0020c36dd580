"""Two `ringswarm fly --shard` processes flying `ringswarm sitl` vehicles over real UDP,
talking to each other over Zenoh on the loopback (tests/fixtures/ground-diamond-shards.toml:
the ground diamond of test_fly.py, one macro-vertex per shard).

What is checked, from each shard's run directory:
- both adopt one consensus start, the same instant on the swarm clock (Unix µs), and
  both predict the same final velocity: every vehicle starts at rest, so (0, 0);
- both fly their own vehicles to the end and land them (exit code 0);
- a shard killed in flight makes the other apply its loss policy (hold).
"""

import os
import subprocess
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
        # (tests/lockstep_shards.rs).
        assert "a vehicle is lost" in row[-1] and row[1] == "", row
        start_row = next(r for r in events(out_a) if START.search(r[-1]))
        assert float(row[0]) > float(start_row[0])
    finally:
        for process, _ in shards.values():
            stop(process)
        stop(sitl)
