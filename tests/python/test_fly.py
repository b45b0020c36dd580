"""`ringswarm fly` flying `ringswarm sitl` vehicles over real UDP (the README's two-terminal
flow), then the run directory read back: summary.json and the .tlog with pymavlink.

The scenario (tests/fixtures/ground-diamond.toml): four x500 vehicles at rest on the
ground, handshaken, climbing to 5 m, forming a diamond for 8 s, landing and disarming.
Expected values: every vehicle starts at rest, so w·v = 0 and the predicted final velocity
is exactly (0, 0); the slowest closed-loop mode of (m=2, k=1, alpha=0.6, beta=1.2) decays
at 0.6 1/s (numpy, ringswarm_ref.closed_loop_abscissa), so the 4 m initial formation error
is below 0.5 m after 8 s.
"""

import csv
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
pytestmark = pytest.mark.xdist_group("test_fly")

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
CONFIG = ROOT / "tests" / "fixtures" / "ground-diamond.toml"
N = 4
RATE_HZ = 50.0
NAV_LAND = mavutil.mavlink.MAV_CMD_NAV_LAND
ARM_DISARM = mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("fly") / "run"
    log = open(out.parent / "sitl.log", "w")
    sitl = subprocess.Popen([BIN, "sitl", "--config", str(CONFIG)], stdout=log, stderr=subprocess.STDOUT)
    try:
        fly = subprocess.run(
            [BIN, "fly", "--config", str(CONFIG), "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=120,
        )
    finally:
        sitl.terminate()
        sitl.wait(timeout=10)
        log.close()
    assert fly.returncode == 0, fly.stderr[-3000:]
    return out


def test_the_law_converges_and_every_vehicle_lands(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["vehicles"] == N
    assert summary["control_rate_hz"] == pytest.approx(RATE_HZ)
    assert summary["predicted_final_velocity"] == pytest.approx([0.0, 0.0], abs=1e-6)
    assert math.hypot(*summary["achieved_final_velocity"]) < 0.1
    assert summary["formation_error_m"] < 0.5
    assert summary["altitude_error_m"] < 0.2
    # The nearest offsets, (-6, 0) and (-2, 4), are 5.66 m apart and the start line is 5 m:
    # no path crosses, nobody comes closer than 3 m.
    assert summary["min_separation_m"] > 3.0
    # The diamond asks for less than the envelope gives (at most 4 m apart at alpha 0.6,
    # beta 1.2): no command was limited.
    assert summary["saturated_fraction"] == 0.0
    # The consensus value: every vehicle starts at rest, so c = Σ w (p − d) / Σ w stays
    # where it starts (w = (1, 2, 1, 2) for k = 1); starts (0, 5, 10, 15 m east) minus
    # the offsets give c = (46, −4) / 6 m, and each vehicle ends at c + dᵢ, not merely in
    # formation somewhere.
    offsets = [(-6.0, 0.0), (-2.0, 4.0), (2.0, -4.0), (6.0, 0.0)]
    c = (46.0 / 6.0, -4.0 / 6.0)
    for i, d in enumerate(offsets):
        with open(run_dir / f"vehicle-{i + 1}.csv") as f:
            rows = [r for r in csv.DictReader(f) if r["swarm_phase"] == "consensus"]
        end = (float(rows[-1]["x_m"]), float(rows[-1]["y_m"]))
        want = (c[0] + d[0], c[1] + d[1])
        assert math.dist(end, want) < 0.5, (i + 1, end, want)
    # Consensus for the configured 8 s, within a control period.
    assert summary["consensus_ended_s"] - summary["consensus_started_s"] == pytest.approx(8.0, abs=0.05)
    assert summary["final_phase"] == "landing"
    # Cross-check the prediction's basis: the slowest mode is what the docstring says.
    assert ref.closed_loop_abscissa(2, 1.0, 0.6, 1.2) == pytest.approx(-0.6, abs=1e-9)


def test_the_tlog_holds_every_setpoint_well_formed_at_the_configured_rate(run_dir):
    messages = read_tlog(run_dir / "traffic.tlog")
    counts = Counter(m.get_type() for m in messages)
    assert counts["BAD_DATA"] == 0
    # Telemetry the coordinator asked for (LOCAL_POSITION_NED, ATTITUDE_QUATERNION at the
    # control rate), heartbeats from every vehicle, setpoints to every vehicle.
    for kind in ("HEARTBEAT", "LOCAL_POSITION_NED", "ATTITUDE_QUATERNION", "SET_ATTITUDE_TARGET", "COMMAND_ACK"):
        assert counts[kind] > 0, kind
    times = defaultdict(list)
    for m in messages:
        if m.get_type() != "SET_ATTITUDE_TARGET":
            continue
        assert m.type_mask == 7
        assert 1 <= m.target_system <= N and m.target_component == 1
        assert math.sqrt(sum(q * q for q in m.q)) == pytest.approx(1.0, abs=1e-6)
        assert 0.0 <= m.thrust <= 1.0
        times[m.target_system].append(m._timestamp)
    assert sorted(times) == list(range(1, N + 1))
    for system, stamps in times.items():
        stamps = np.array(stamps)
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        assert rate == pytest.approx(RATE_HZ, rel=0.05), f"vehicle {system}: {rate:.2f} Hz"


def test_every_vehicle_was_told_to_land_and_disarm_and_acknowledged_both(run_dir):
    messages = read_tlog(run_dir / "traffic.tlog")
    told = defaultdict(set)
    acked = defaultdict(set)
    for m in messages:
        if m.get_type() == "COMMAND_LONG" and m.command == NAV_LAND:
            told[m.target_system].add("land")
        if m.get_type() == "COMMAND_LONG" and m.command == ARM_DISARM and m.param1 == 0.0:
            told[m.target_system].add("disarm")
        if m.get_type() == "COMMAND_ACK" and m.result == 0 and m.command in (NAV_LAND, ARM_DISARM):
            acked[m.get_srcSystem()].add(m.command)
    for system in range(1, N + 1):
        assert told[system] == {"land", "disarm"}, system
        assert acked[system] == {NAV_LAND, ARM_DISARM}, system
    # Each vehicle's last EXTENDED_SYS_STATE says it is on the ground.
    last = {}
    for m in messages:
        if m.get_type() == "EXTENDED_SYS_STATE":
            last[m.get_srcSystem()] = m.landed_state
    for system in range(1, N + 1):
        assert last[system] == mavutil.mavlink.MAV_LANDED_STATE_ON_GROUND, system


def test_the_coordinator_heartbeat_is_in_the_tlog_at_one_hertz_per_link(run_dir):
    """Over UDP the four links' heartbeats leave within the same wall-clock second: the
    tlog holds about 4 per second of flight, from 253/190, type GCS."""
    messages = read_tlog(run_dir / "traffic.tlog")
    beats = [m for m in messages if m.get_type() == "HEARTBEAT" and m.type == mavutil.mavlink.MAV_TYPE_GCS]
    assert beats
    assert all((m.get_srcSystem(), m.get_srcComponent()) == (253, 190) for m in beats)
    assert all(m.autopilot == mavutil.mavlink.MAV_AUTOPILOT_INVALID for m in beats)
    span = messages[-1]._timestamp - messages[0]._timestamp
    rate = len(beats) / span
    assert rate == pytest.approx(N * 1.0, rel=0.1), f"{rate:.2f} heartbeats/s for {N} links"


def test_flight_mcap_reads_with_the_formats_own_reader_and_ends_in_the_formation(run_dir):
    """flight.mcap, read with the MCAP project's Python reader: the four channels with
    JSON schemas, one /swarm state and one /setpoints message per 50 ms, every event on
    /log at its CSV time, and summary.json on /summary; the last /swarm state puts each
    vehicle where its CSV does (ENU, 0.1 mm), the last /setpoints gives its CSV row's
    commands."""
    from mcap.reader import make_reader

    with open(run_dir / "flight.mcap", "rb") as f:
        reader = make_reader(f)
        topics = {}
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json"
            assert schema.encoding == "jsonschema"
            json.loads(schema.data)
            topics.setdefault(channel.topic, []).append((message.log_time, json.loads(message.data)))
    assert set(topics) == {"/swarm", "/setpoints", "/log", "/summary"}
    assert [t for t, _ in topics["/setpoints"]] == [t for t, _ in topics["/swarm"]]
    swarm = topics["/swarm"]
    start_ns = swarm[0][0]
    steps = [t - start_ns for t, _ in swarm]
    assert steps == [i * 50_000_000 for i in range(len(swarm))]
    with open(run_dir / "events.csv") as f:
        events = list(csv.DictReader(f))
    assert len(topics["/log"]) == len(events)
    for (t_ns, log), event in zip(topics["/log"], events):
        assert (t_ns - start_ns) * 1e-9 == pytest.approx(float(event["t_s"]), abs=1e-6)
        assert log["level"] == (3 if event["level"] == "warning" else 2)
    summary = json.loads((run_dir / "summary.json").read_text())
    assert topics["/summary"] == [(topics["/summary"][0][0], summary)]
    t_last, last = swarm[-1]
    for i in range(N):
        with open(run_dir / f"vehicle-{i + 1}.csv") as f:
            rows = [r for r in csv.DictReader(f) if float(r["t_s"]) <= last["t_s"] + 1e-9]
        want = [float(rows[-1][k]) for k in ("x_m", "y_m", "z_m")]
        assert last["vehicles"][i]["position_enu_m"] == pytest.approx(want, abs=1e-4)
        sent = topics["/setpoints"][-1][1]["vehicles"][i]
        assert sent["sysid"] == i + 1
        want = [float(rows[-1][k]) for k in ("cmd_ax_mps2", "cmd_ay_mps2", "cmd_az_mps2")]
        assert sent["command_enu_mps2"] == want
        assert sent["thrust_norm"] == float(rows[-1]["sp_thrust_norm"])


def test_sigterm_lands_the_swarm_and_writes_the_run_directory(tmp_path):
    """What `timeout`, systemd and `docker stop` send: `fly` lands every vehicle and
    writes its run directory, as for Ctrl-C, and exits 0 once they are down."""
    import signal
    import threading
    import time

    out = tmp_path / "run"
    log = open(tmp_path / "sitl.log", "w")
    sitl = subprocess.Popen([BIN, "sitl", "--config", str(CONFIG)], stdout=log, stderr=subprocess.STDOUT)
    fly = subprocess.Popen([BIN, "fly", "--config", str(CONFIG), "--out", str(out)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(fly.stderr), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not any("consensus" in line for line in list(lines)):
            time.sleep(0.1)
        assert any("consensus" in line for line in list(lines)), "".join(lines)[-2000:]
        fly.send_signal(signal.SIGTERM)
        fly.wait(timeout=60)
    finally:
        if fly.poll() is None:
            fly.kill()
        sitl.send_signal(signal.SIGTERM)
        sitl.wait(timeout=10)
        log.close()
    reader.join(timeout=5)
    assert fly.returncode == 0, "".join(lines)[-3000:]
    assert sitl.returncode == 0
    assert any("SIGTERM: landing every vehicle" in line for line in lines), "".join(lines)[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "requested"
    assert summary["final_phase"] == "landing"
    # Every vehicle was told to land and disarmed on the ground.
    messages = read_tlog(out / "traffic.tlog")
    landed = {m.target_system for m in messages
              if m.get_type() == "COMMAND_LONG" and m.command == NAV_LAND}
    assert landed == set(range(1, N + 1)), landed
    disarmed = {m.target_system for m in messages
                if m.get_type() == "COMMAND_LONG" and m.command == ARM_DISARM and m.param1 == 0}
    assert disarmed == set(range(1, N + 1)), disarmed
