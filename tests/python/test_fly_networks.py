"""`ringswarm sitl --config F` + `ringswarm fly --config F` with 84 vehicles on two MAVLink
networks whose system ids overlap (1..42 on each): more vehicles than PX4 SITL's ports
allow (they collide from the 41st), one coordinator socket per network, vehicles told
apart by system id and found from their frames.

The ring (scripts/ring_config.py): k = 1, so w = (1, 2, 1, 2, ...); every vehicle flies
1 m/s east, agents 1, 3, 5, ... (paper numbering) 0.2 m/s south and the others 0.2 m/s
north, so the predicted final velocity is sum(w v)/sum(w) = (1, (2*0.2 - 0.2)/3) m/s.
"""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

# One worker runs this module, so its module-scoped flight is flown once.
pytestmark = pytest.mark.xdist_group("test_fly_networks")

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
N, PER_NETWORK = 84, 42


def predicted():
    w = [1.0 if i % 2 == 0 else 2.0 for i in range(N)]
    north = [-0.2 if i % 2 == 0 else 0.2 for i in range(N)]
    return [sum(w) / sum(w), sum(a * b for a, b in zip(w, north)) / sum(w)]


def recorded_prediction(run_dir):
    """Σ wᵢvᵢ / Σ wᵢ of each vehicle's velocity on its first consensus row (ENU: vx east,
    vy north), in the ring's agent order (agent i is system id i % 42 + 1 on network i // 42)."""
    w = [1.0 if i % 2 == 0 else 2.0 for i in range(N)]
    east = north = 0.0
    for i in range(N):
        with open(run_dir / f"vehicle-n{i // PER_NETWORK}-{i % PER_NETWORK + 1}.csv") as f:
            row = next(r for r in csv.DictReader(f) if r["swarm_phase"] == "consensus")
        east += w[i] * float(row["vx_mps"])
        north += w[i] * float(row["vy_mps"])
    return [east / sum(w), north / sum(w)]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("networks")
    out = tmp / "run"
    analysis = subprocess.run([BIN, "analyze", "-m", str(N // 2), "-k", "1", "--json"], capture_output=True, text=True, check=True)
    bound = json.loads(analysis.stdout)["yu_bound"]
    config = tmp / "ring.toml"
    text = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "ring_config.py"), str(N), "--yu-bound", str(bound), "--per-network", str(PER_NETWORK), "--duration", "6", "--port", "14700"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    config.write_text(text)
    log = open(tmp / "sitl.log", "w")
    sitl = subprocess.Popen([BIN, "sitl", "--config", str(config)], stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    fly = subprocess.Popen([BIN, "fly", "--config", str(config), "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # The ring ends by hovering: once the status line says so, Ctrl-C twice.
        deadline = time.monotonic() + 120
        for line in fly.stderr:
            if "ended (hovering)" in line or time.monotonic() > deadline:
                break
        fly.send_signal(signal.SIGINT)
        time.sleep(1.0)
        fly.send_signal(signal.SIGINT)
        stdout, stderr = fly.communicate(timeout=60)
    finally:
        if fly.poll() is None:
            fly.kill()
        sitl.send_signal(signal.SIGINT)
        sitl.wait(timeout=20)
        log.close()
    assert (out / "summary.json").exists(), stderr[-3000:]
    return out


def test_every_vehicle_of_both_networks_flew_the_law(run_dir):
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["vehicles"] == N
    assert summary["failure"] is None
    # The prediction is Σ wᵢvᵢ / Σ wᵢ of the velocities at the start of consensus. Recomputed
    # from the vehicles' own records (velocities written to 1e-4 m/s), it matches to the
    # rounding of the file.
    assert summary["predicted_final_velocity"] == pytest.approx(recorded_prediction(run_dir), abs=1e-4)
    # The vehicles hold their configured velocities through the handshake, but in real time
    # on a loaded machine the hold drifts: 5.3e-4 m/s was seen on CI with other tests
    # running beside it. 0.005 m/s is a tenth of the smallest configured component.
    assert summary["predicted_final_velocity"] == pytest.approx(predicted(), abs=0.005)
    got = summary["achieved_final_velocity"]
    assert abs(got[0] - predicted()[0]) < 0.02 and abs(got[1] - predicted()[1]) < 0.02, got


def test_the_same_system_id_on_two_networks_is_two_vehicles(run_dir):
    files = sorted(p.name for p in run_dir.glob("vehicle-*.csv"))
    assert len(files) == N
    assert "vehicle-n0-1.csv" in files and "vehicle-n1-1.csv" in files
    flying = {}
    for name in files:
        with open(run_dir / name) as f:
            rows = list(csv.DictReader(f))
        flying[name] = [r for r in rows if r["link_phase"] == "flying"]
    # Every vehicle was flown, and the two system-id-1 vehicles are on opposite sides of
    # the ring (agents 1 and 43 of 84: 180 degrees apart on a circle of radius 66.8 m).
    assert all(flying.values()), [n for n, rows in flying.items() if not rows]
    a, b = (flying[n][0] for n in ("vehicle-n0-1.csv", "vehicle-n1-1.csv"))
    gap = ((float(a["x_m"]) - float(b["x_m"])) ** 2 + (float(a["y_m"]) - float(b["y_m"])) ** 2) ** 0.5
    radius = 5.0 * N / (2 * 3.141592653589793)
    assert gap == pytest.approx(2 * radius, abs=2.0)
