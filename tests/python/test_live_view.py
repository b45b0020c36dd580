"""The live view in headless Chromium, the replay page, and a pymavlink listener on a
traffic mirror, around one `demo --realtime --web --mirror` flight of
tests/fixtures/ground-diamond.toml (four x500, 8 s of formation, 50 Hz control).

The mirror is checked against the run directory's traffic.tlog (every frame the
coordinator sent and received, stamped in flight time): the listener must see the same
SET_ATTITUDE_TARGET frames, and the tlog says they went out at the control rate.
"""

import json
import os
import shutil
import socket
import subprocess
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import pytest
from pymavlink import mavutil
from selenium import webdriver
from selenium.webdriver.chrome.service import Service

from tlog import read_tlog

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))
CONFIG = ROOT / "tests" / "fixtures" / "ground-diamond.toml"
VEHICLES = [1, 2, 3, 4]
CONTROL_RATE_HZ = 50.0
FORCE_DISARM = 21196.0  # MAV_CMD_COMPONENT_ARM_DISARM param2: disarm even in the air


def free_port(kind=socket.SOCK_STREAM):
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(what, check, timeout_s=60.0, every_s=0.1):
    """Polls `check` until it returns something truthy; fails naming `what`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(every_s)
    pytest.fail(f"timed out after {timeout_s} s waiting for {what}")


def browser():
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if chromium is None or driver_path is None:
        pytest.fail("chromium and chromedriver are needed (scripts/test.sh installs them)")
    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for flag in [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--window-size=1400,900",
        f"--user-data-dir={tempfile.mkdtemp(prefix='ringswarm-chromium-')}",
    ]:
        options.add_argument(flag)
    return webdriver.Chrome(service=Service(executable_path=driver_path), options=options)


class MirrorListener:
    """Reads the mirror for the whole flight; answers it once with a forced disarm."""

    def __init__(self, port):
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=251)
        # Python reads slower than four vehicles' traffic arrives while Chromium draws on
        # the same cores: a large receive buffer keeps the kernel from dropping what the
        # listener has not read yet (what is checked is the mirror, not this thread).
        # SO_RCVBUFFORCE (Linux, root) passes net.core.rmem_max; SO_RCVBUF is capped by it.
        try:
            self.conn.port.setsockopt(socket.SOL_SOCKET, 33, 8 << 20)
        except OSError:
            self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.telemetry = Counter()
        self.attitude_targets = Counter()
        self.sent_back = 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        while not self.stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.2)
            if msg is None:
                continue
            kind = msg.get_type()
            if kind in ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION") and msg.get_srcComponent() == 1:
                self.telemetry[(msg.get_srcSystem(), kind)] += 1
            elif kind == "SET_ATTITUDE_TARGET":
                self.attitude_targets[msg.target_system] += 1
                if self.sent_back == 0 and sum(self.attitude_targets.values()) > 200:
                    # In flight: a forced disarm of vehicle 1 back through the mirror.
                    self.conn.mav.command_long_send(
                        1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                        0.0, FORCE_DISARM, 0, 0, 0, 0, 0)
                    self.sent_back += 1

    def close(self):
        self.stop.set()
        self.thread.join(timeout=5)
        self.conn.close()


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    """One real-time flight. Chromium is started before the flight, so that a slow
    browser start on a loaded machine cannot make the page miss the formation."""
    out = tmp_path_factory.mktemp("live") / "run"
    web_port, mirror_port = free_port(), free_port(socket.SOCK_DGRAM)
    listener = MirrorListener(mirror_port)
    driver = browser()
    demo = subprocess.Popen(
        [BIN, "demo", "--realtime", "--scenario", str(CONFIG), "--out", str(out),
         "--web", f"127.0.0.1:{web_port}", "--mirror", f"127.0.0.1:{mirror_port}"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    result = {"demo": demo, "out": out, "url": f"http://127.0.0.1:{web_port}/",
              "listener": listener, "driver": driver}
    try:
        yield result
    finally:
        driver.quit()
        if demo.poll() is None:
            demo.kill()
        listener.close()


def finished(flight):
    demo = flight["demo"]
    stdout, stderr = demo.communicate(timeout=120)
    assert demo.returncode == 0, stderr
    return stdout, stderr


@pytest.mark.xdist_group("live-flight")
def test_the_live_page_the_state_api_and_the_websocket_rate(flight):
    """All checks of the live page in one test, on the browser started before the flight:
    split over tests, a later one could find the flight over and the server gone."""
    import urllib.request
    driver = flight["driver"]

    # The page is up once the flight has bound its port.
    def opened():
        try:
            driver.get(flight["url"])
            return driver.find_elements("css selector", "#vehicles tbody tr[data-sysid]")
        except Exception:
            return None
    rows = wait_for("the live page", opened, timeout_s=60, every_s=0.5)
    sysids = sorted(int(r.get_attribute("data-sysid")) for r in rows)
    assert sysids == VEHICLES

    # The state API answers while the flight is on.
    state = json.loads(urllib.request.urlopen(flight["url"] + "api/state", timeout=30).read())
    assert [v["sysid"] for v in state["vehicles"]] == VEHICLES
    for v in state["vehicles"]:
        assert set(v) >= {"sysid", "network", "position_enu_m", "velocity_enu_mps", "link_phase"}
    assert "predicted_final_velocity" in state and "phase" in state

    # Every vehicle drawn, and drawn moving: from a line on the ground into the diamond.
    drawn = lambda: driver.execute_script("return window.ringswarmView.drawn")
    first = wait_for("every vehicle drawn", lambda: (d := drawn()) and len(d) == 4 and d)
    first = {d["sysid"]: d for d in first}

    def moved():
        now = {d["sysid"]: d for d in drawn()}
        return max(abs(now[s]["x_m"] - first[s]["x_m"]) + abs(now[s]["y_m"] - first[s]["y_m"])
                   for s in now) > 1.0 and now
    later = wait_for("the drawn positions to change by over a metre", moved, timeout_s=60)
    assert any(abs(later[s]["x_px"] - first[s]["x_px"]) + abs(later[s]["y_px"] - first[s]["y_px"]) > 1
               for s in later)
    # The table fills in: every vehicle's link phase and mode.
    cells = driver.execute_script(
        "return [...document.querySelectorAll('#vehicles tbody tr')].map(r => [...r.children].map(c => c.textContent))")
    assert len(cells) == 4
    assert all(c[2] in ("flying", "landing", "disarming", "done") for c in cells), cells
    assert all(c[3] != "–" for c in cells), cells

    # The WebSocket: count the states the page gets over 3 s of flight.
    start = driver.execute_script("return window.ringswarmView.frames")
    t0 = driver.execute_script("return window.ringswarmView.state.t_s")
    time.sleep(3.0)
    frames = driver.execute_script("return window.ringswarmView.frames") - start
    t1 = driver.execute_script("return window.ringswarmView.state.t_s")
    assert start >= 2
    if t1 - t0 > 1.0:  # still flying: the states kept coming
        assert frames / (t1 - t0) >= 10.0, f"{frames} states in {t1 - t0:.2f} s of flight"


@pytest.mark.xdist_group("live-flight")
def test_the_mirror_carries_every_vehicle_and_ignores_what_comes_back(flight):
    _, stderr = finished(flight)
    listener = flight["listener"]
    time.sleep(0.5)
    listener.close()
    out = flight["out"]
    summary = json.loads((out / "summary.json").read_text())
    # The forced disarm sent back changed nothing: the flight went to its end and landed.
    assert listener.sent_back == 1
    assert summary["final_phase"] == "landing"
    assert summary["failure"] is None
    assert summary["formation_error_m"] < 0.5
    mirror = summary["mirrors"][0]
    assert mirror["dropped_inbound_datagrams"] >= 1
    assert mirror["not_sent_datagrams"] == 0
    messages = read_tlog(out / "traffic.tlog")
    assert not [m for m in messages if m.get_type() == "COMMAND_LONG" and m.param2 == FORCE_DISARM]
    # Every vehicle's telemetry reached the listener.
    for sysid in VEHICLES:
        for kind in ("LOCAL_POSITION_NED", "ATTITUDE_QUATERNION"):
            assert listener.telemetry[(sysid, kind)] > 50, (sysid, kind, listener.telemetry)
    # The setpoints: the tlog has them at the control rate (flight time stamps), and the
    # listener saw them all (loopback; allow 1 % lost in the kernel).
    for sysid in VEHICLES:
        stamps = [m._timestamp for m in messages
                  if m.get_type() == "SET_ATTITUDE_TARGET" and m.target_system == sysid]
        assert len(stamps) > 100
        rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        assert abs(rate - CONTROL_RATE_HZ) < 0.05 * CONTROL_RATE_HZ, (sysid, rate)
        seen = listener.attitude_targets[sysid]
        assert len(stamps) * 0.99 <= seen <= len(stamps), (sysid, seen, len(stamps))


def open_page(driver, port):
    """Loads the page of a `view` server once it answers; its vehicle rows."""
    def opened():
        try:
            driver.get(f"http://127.0.0.1:{port}/")
            return driver.find_elements("css selector", "#vehicles tbody tr[data-sysid]")
        except Exception:
            return None
    return wait_for("the replay page", opened, timeout_s=60, every_s=0.5)


def test_the_replay_page_of_a_lockstep_run_moves_with_its_slider(tmp_path):
    out = tmp_path / "run"
    subprocess.run([BIN, "demo", "--scenario", str(CONFIG), "--out", str(out), "--no-plots"],
                   check=True, capture_output=True, timeout=300)
    port = free_port()
    view = subprocess.Popen([BIN, "view", str(out), "--web", f"127.0.0.1:{port}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    driver = browser()
    try:
        rows = open_page(driver, port)
        assert sorted(int(r.get_attribute("data-sysid")) for r in rows) == VEHICLES
        assert driver.find_element("id", "replay").is_displayed()
        duration = float(driver.find_element("id", "slider").get_attribute("max"))
        assert duration > 8.0
        at = lambda: driver.execute_script("return window.ringswarmView.state && window.ringswarmView.state.t_s")
        drawn = lambda: {d["sysid"]: d for d in driver.execute_script("return window.ringswarmView.drawn")}

        def slide_to(t):
            # As a user drags the slider.
            driver.execute_script(
                "const s = document.getElementById('slider'); s.value = arguments[0];"
                "s.dispatchEvent(new Event('input'));", str(t))
            wait_for(f"the state at {t} s", lambda: abs((at() or -1) - t) < 0.06)
            return drawn()

        wait_for("the state at 0 s", lambda: at() == 0)
        # The first half second at which every vehicle's position was recorded.
        for t in [0.5 * i for i in range(1, 9)]:
            early = slide_to(t)
            if len(early) == 4:
                break
        assert sorted(early) == VEHICLES
        middle = slide_to(round(duration / 2, 2))
        assert sorted(middle) == VEHICLES
        # On the ground in a line at first, in the diamond mid-flight: someone moved.
        assert max(abs(middle[s]["x_m"] - early[s]["x_m"]) + abs(middle[s]["y_m"] - early[s]["y_m"])
                   for s in VEHICLES) > 1.0
        phase = driver.find_element("id", "phase").text
        assert phase in ("consensus", "landing", "ended"), phase
    finally:
        driver.quit()
        view.terminate()
        view.wait(timeout=30)


def test_the_replay_draws_the_fence_the_separation_circles_and_the_closest_pair(tmp_path):
    """crossing.toml (eight x500s through the centre) inside a circle of 80 m: the page
    draws the fence, one separation circle per vehicle, and names the closest pair."""
    config = tmp_path / "fenced-crossing.toml"
    text = (ROOT / "config" / "crossing.toml").read_text()
    fence = ('[fence]\nkind = "circle"\ncentre_enu_m = [0.0, 0.0]\nradius_m = 80.0\n'
             'min_altitude_m = 20.0\nmax_altitude_m = 100.0\n\n[[vehicle]]')
    config.write_text(text.replace("[[vehicle]]", fence, 1))
    out = tmp_path / "run"
    done = subprocess.run([BIN, "demo", "--scenario", str(config), "--out", str(out), "--no-plots"],
                          capture_output=True, text=True, timeout=300)
    # The swarm flies out at (2, 1) m/s and the fence stops it: exit code 5.
    assert done.returncode == 5, done.stderr
    port = free_port()
    view = subprocess.Popen([BIN, "view", str(out), "--web", f"127.0.0.1:{port}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    driver = browser()
    try:
        open_page(driver, port)
        driver.execute_script(
            "const s = document.getElementById('slider'); s.value = '12';"
            "s.dispatchEvent(new Event('input'));")
        at = lambda: driver.execute_script("return window.ringswarmView.state && window.ringswarmView.state.t_s")
        wait_for("the state at 12 s", lambda: abs((at() or -1) - 12) < 0.06)
        drawn = driver.execute_script("return window.ringswarmView.drawnSafety")
        assert drawn["fence"] == "circle"
        assert drawn["circles"] == 8
        a, b, distance = drawn["closest"]
        assert a != b and distance >= 2.85, drawn
        closest = driver.find_element("id", "closest").text
        assert closest.startswith(f"{a}–{b}: ") and closest.endswith("(separation 3.0 m)"), closest
    finally:
        driver.quit()
        view.terminate()
        view.wait(timeout=30)
