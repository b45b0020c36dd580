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
    # Vehicle 1 starts at the south-west corner and is sent to the north-east one.
    assert "start_enu_m = [-6.000, -6.000, 50.0]" in text
    assert "offsets_m = [[6.000, 6.000]," in text
    out = tmp_path / "run"
    done = subprocess.run([BIN, "demo", "--scenario", str(config), "--out", str(out), "--no-plots"], capture_output=True, text=True, timeout=600)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["safety"]["min_separation_seen_m"] >= 0.95 * 3.0, summary["safety"]
    assert summary["safety"]["filtered_ticks"] > 0
    assert done.returncode == 0, done.stderr[-2000:]


def test_a_block_with_an_odd_number_of_vehicles_is_refused_by_name():
    done = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "block_config.py"), "3", "--yu-bound", "10", "--time-scale", "0.5"],
        capture_output=True, text=True,
    )
    assert done.returncode != 0
    assert "even number of vehicles" in done.stderr
