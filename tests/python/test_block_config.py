"""scripts/block_config.py writes a packed block swap that `ringswarm demo` flies: a 4 x 4
block 4 m apart, each vehicle sent to its start mirrored through the centre, places in
vehicle order. The filter keeps 3 m (at least 95 % of it counts as kept) while every path
crosses the centre."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))


def refused(*args):
    """The script's standard error for `args`, which it must refuse (a non-zero exit)."""
    done = subprocess.run([sys.executable, str(ROOT / "scripts" / "block_config.py"), *args], capture_output=True, text=True)
    assert done.returncode != 0, done.stdout[:200]
    return done.stderr


def test_the_block_swap_flies_apart_with_its_places_mirrored(tmp_path):
    config = tmp_path / "block.toml"
    # Yu's bound for m = 8 at k = 1 is below 10, so beta = sqrt(12.5) keeps 25 % above it.
    text = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "block_config.py"), "4", "--yu-bound", "10", "--time-scale", "0.5", "--duration", "20"],
        check=True, capture_output=True, text=True,
    ).stdout
    config.write_text(text)
    assert text.count("[[vehicle]]") == 16
    assert 'assign = "fixed"' in text
    # The filter's 2 ms of the 20 ms period.
    assert "control_rate_hz = 50.0" in text
    assert "budget_share = 0.1\n" in text
    # Vehicle 1 starts at the south-west corner and is sent to the north-east one.
    assert "start_enu_m = [-6.000, -6.000, 50.0]" in text
    assert "offsets_m = [[6.000, 6.000]," in text
    out = tmp_path / "run"
    done = subprocess.run([BIN, "demo", "--scenario", str(config), "--out", str(out), "--no-plots"], capture_output=True, text=True, timeout=600)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["safety"]["min_separation_seen_m"] >= 0.95 * 3.0, summary["safety"]
    assert summary["safety"]["filtered_ticks"] > 0
    # Where and when that closest distance was seen: two of the 16, named as the events
    # name them (network and system id), inside the flight.
    pair = summary["safety"]["min_separation_seen_pair"]
    assert len(pair) == 2 and pair[0] != pair[1], pair
    assert all(v.startswith("n0-") and 1 <= int(v[3:]) <= 16 for v in pair), pair
    assert 0.0 <= summary["safety"]["min_separation_seen_at_s"] <= 30.0, summary["safety"]
    assert summary["safety"]["min_separation_seen_phase"] in ("handshake", "consensus", "ended"), summary["safety"]
    assert done.returncode == 0, done.stderr[-2000:]


def test_the_emulated_vehicles_boot_rate_is_written_and_checked():
    args = ["4", "--yu-bound", "10", "--time-scale", "0.5"]
    text = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "block_config.py"), *args, "--telemetry-rate-hz", "10"],
        check=True, capture_output=True, text=True,
    ).stdout
    assert "[emulator]\nground_below_m = 100.0\ntelemetry_rate_hz = 10\n" in text
    assert "--telemetry-rate-hz must be in (0, 1000]" in refused(*args, "--telemetry-rate-hz", "0")


def test_a_block_with_an_odd_number_of_vehicles_is_refused_by_name():
    assert "even number of vehicles" in refused("3", "--yu-bound", "10", "--time-scale", "0.5")


def test_a_filter_budget_longer_than_the_control_period_is_refused_by_name():
    assert "--budget-ms must be in (0, 20]" in refused("4", "--yu-bound", "10", "--time-scale", "0.5", "--budget-ms", "25")


def test_a_sharded_block_gives_each_shard_whole_networks_of_equal_size():
    # 1024 vehicles in 4 shards: 256 each, more than one network (250) holds, so each shard
    # takes two networks of 128; shard s listens on 7500 + s and connects to every earlier one.
    text = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "block_config.py"), "32", "--yu-bound", "10", "--time-scale", "0.01", "--shards", "4"],
        check=True, capture_output=True, text=True,
    ).stdout
    assert text.count("[[vehicle]]") == 1024
    assert text.count("[[shard]]") == 4
    assert text.count("[[network]]") == 8
    assert 'watch = "all"' in text
    shards = text.split("[[shard]]")[1:]
    for s, block in enumerate(shards):
        listed = block.split("vehicles = [", 1)[1].split("]\n", 1)[0]
        assert listed.count("system_id") == 256
        nets = {f"n{2 * s}", f"n{2 * s + 1}"}
        assert {part.split('"')[1] for part in listed.split("network = ")[1:]} == nets
        assert "system_id = 128, network" in listed and "system_id = 129," not in listed
        assert f'listen = ["tcp/127.0.0.1:{7500 + s}"]' in block
        assert block.count("tcp/127.0.0.1:") == 1 + s


def test_shards_that_do_not_divide_the_block_are_refused_by_name():
    assert "--shards must divide the 16 vehicles evenly, got 3" in refused("4", "--yu-bound", "10", "--time-scale", "0.5", "--shards", "3")
