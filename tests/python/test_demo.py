"""`ringswarm demo` (paper-sim1 in lockstep) read back from its run directory: the summary
against the hand-derived prediction, and the .tlog with pymavlink.

Expected values: w = (1, 6, 1, 6, 1, 6) for k = 5, so v_f = sum(w v0) / 21 =
(271/21, 157/21) from the paper's initial velocities (recomputed with numpy in
ringswarm_ref.final_velocity); the lockstep runs in virtual time, so the setpoint
stream is exactly the configured 250 Hz.
"""

import json
import math
import os
import subprocess
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

import ringswarm_ref as ref
from tlog import read_tlog

# One worker runs this module, so its module-scoped flight is flown once.
pytestmark = pytest.mark.xdist_group("test_demo")

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
V0 = [(9, 4), (15, 8), (18, -2), (13, 1), (-8, -7), (14, 18)]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "run"
    done = subprocess.run([BIN, "demo", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "| achieved final velocity |" in done.stdout
    return out


@pytest.fixture(scope="module")
def tlog(run_dir):
    """Every message of the run's .tlog, read once for the tests that need it (pure-Python
    parsing of a 167 s run is the slow part)."""
    return read_tlog(run_dir / "traffic.tlog")


def test_summary_matches_the_independent_prediction(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    expected = ref.final_velocity(np.array(V0, dtype=float), 5.0)
    assert expected == pytest.approx([271 / 21, 157 / 21], abs=1e-12)
    assert summary["predicted_final_velocity"] == pytest.approx(expected, abs=0.05)
    achieved = np.array(summary["achieved_final_velocity"])
    assert np.linalg.norm(achieved - expected) <= 0.01 * np.linalg.norm(expected)
    assert summary["formation_error_m"] < 0.5
    assert summary["altitude_error_m"] < 0.5
    assert summary["final_phase"] == "landing"


def test_tlog_setpoints_are_well_formed_and_at_250_hz(tlog):
    counts = Counter()
    stamps = defaultdict(list)
    for m in tlog:
        kind = m.get_type()
        counts[kind] += 1
        if kind != "SET_ATTITUDE_TARGET":
            continue
        assert m.type_mask == 7
        assert m.target_component == 1
        assert math.sqrt(sum(q * q for q in m.q)) == pytest.approx(1.0, abs=1e-6)
        assert 0.0 <= m.thrust <= 1.0
        stamps[m.target_system].append(m._timestamp)
    assert counts["BAD_DATA"] == 0
    assert sorted(stamps) == [1, 2, 3, 4, 5, 6]
    # Telemetry asked at the control rate: as many positions as attitudes, from 6 vehicles.
    assert counts["LOCAL_POSITION_NED"] == counts["ATTITUDE_QUATERNION"] > 6 * 250 * 60
    for system, t in stamps.items():
        t = np.array(t)
        # 50 s of the consensus phase: it starts 1.2 s after the first setpoint (the
        # pre-arm stream) and lasts 60 s.
        start = t[0] + 1.5
        window = t[(t >= start) & (t < start + 50.0)]
        rate = len(window) / 50.0
        assert rate == pytest.approx(250.0, rel=0.05), f"vehicle {system}: {rate:.2f} Hz"


FIGURES = ["trajectories-3d", "paths-xy", "altitude", "velocity", "attitude", "commands"]


def test_the_coordinator_heartbeat_is_in_the_tlog_at_one_hertz(run_dir, tlog):
    """Six vehicle links, each with a 1 Hz GCS heartbeat from the coordinator's own ids
    (253/190); the tlog is stamped with the run's start plus virtual time."""
    stamps = []
    for m in tlog:
        if m.get_type() == "HEARTBEAT" and m.type == mavutil.mavlink.MAV_TYPE_GCS:
            assert (m.get_srcSystem(), m.get_srcComponent()) == (253, 190)
            assert m.autopilot == mavutil.mavlink.MAV_AUTOPILOT_INVALID
            stamps.append(m._timestamp)
    seconds = json.loads((run_dir / "summary.json").read_text())["sim_seconds"]
    assert abs(len(stamps) - 6 * seconds) <= 6 + 0.01 * 6 * seconds, (len(stamps), seconds)
    # Every link sends its first at once; link k of 6 sends the later ones k/6 s after
    # the whole seconds since, so that a swarm's heartbeats are not one burst: six
    # phases a sixth of a second apart, each at 1 Hz.
    t0 = min(stamps)
    first = [t for t in stamps if t - t0 < 0.5]
    assert len(first) == 6, first
    by_phase = {}
    for t in stamps:
        if t - t0 < 0.5:
            continue
        sixths = ((t - t0) % 1.0) * 6.0
        k = round(sixths) % 6
        assert abs(sixths - round(sixths)) < 0.01 * 6, (t, sixths)
        by_phase.setdefault(k, []).append(t)
    assert sorted(by_phase) == list(range(6)), sorted(by_phase)
    for k, times in by_phase.items():
        gaps = np.diff(sorted(times))
        assert np.all(np.abs(gaps - 1.0) < 0.01), (k, gaps[np.abs(gaps - 1.0) >= 0.01])


def test_every_figure_is_written_as_png_and_svg_with_axes_and_legends(run_dir):
    import struct

    for name in FIGURES:
        png = (run_dir / f"{name}.png").read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n", name
        width, height = struct.unpack(">II", png[16:24])  # IHDR
        assert (width, height) == (1100, 700), name
        svg = (run_dir / f"{name}.svg").read_text()
        assert svg.lstrip().startswith("<svg"), name
        assert "vehicle 1" in svg and "vehicle 6" in svg, f"{name}: legend"
    velocity = (run_dir / "velocity.svg").read_text()
    assert "predicted final velocity" in velocity and "time (s)" in velocity and "vx (m/s)" in velocity
    commands = (run_dir / "commands.svg").read_text()
    assert "thrust limits" in commands and "tilt limit at hover" in commands
    paths = (run_dir / "paths-xy.svg").read_text()
    assert "final formation" in paths and "x east (m)" in paths
