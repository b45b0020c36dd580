#!/usr/bin/env python3
"""Real-time bench: paper-sim1 flown by one process, then by three shards in three
network namespaces (veth pairs on a bridge) over Zenoh, and the two compared.

    sudo python3 scripts/shards_netns_bench.py [--bin target/release/ringswarm] [--duration-s 40]

Each flight is `ringswarm sitl` plus `ringswarm fly` (one pair per namespace for the
shards), consensus for `--duration-s`, then landing. Prints one table row per flight
(and per shard) from the run directories' summary.json: the prediction, the velocity
error, the formation error at the end of consensus, the late control ticks and the age
of the states the law flew on. The formation is measured from each vehicle's own
coordinator (its CSV, fresh telemetry), at one instant after the consensus start adopted by
every shard: a shard's own summary counts the other shards' vehicles at their last
reported (older) positions. Needs root (namespaces) and iproute2.
"""

import argparse
import csv
import json
import math
import re
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "config" / "paper-sim1.toml"
SHARDS = ("a", "b", "c")


def sh(*args):
    subprocess.run(args, check=True, capture_output=True, text=True)


def make_hosts(tag):
    """A namespace for the one-process flight, and three on a bridge for the shards."""
    names = {s: f"{tag}{s}" for s in SHARDS}
    hub, one = f"{tag}h", f"{tag}o"
    made = []
    for ns in [hub, one, *names.values()]:
        sh("ip", "netns", "add", ns)
        made.append(ns)
    sh("ip", "-n", one, "link", "set", "lo", "up")
    sh("ip", "-n", hub, "link", "add", "br0", "type", "bridge")
    sh("ip", "-n", hub, "link", "set", "br0", "up")
    for n, s in enumerate(SHARDS, start=1):
        ns = names[s]
        sh("ip", "-n", hub, "link", "add", f"h{s}", "type", "veth", "peer", "name", "eth0", "netns", ns)
        sh("ip", "-n", hub, "link", "set", f"h{s}", "master", "br0")
        sh("ip", "-n", hub, "link", "set", f"h{s}", "up")
        sh("ip", "-n", ns, "addr", "add", f"10.77.0.{n}/24", "dev", "eth0")
        sh("ip", "-n", ns, "link", "set", "eth0", "up")
        sh("ip", "-n", ns, "link", "set", "lo", "up")
    return one, names, made


def shard_config(tmp):
    text = BASE.read_text() + '\n[distributed]\nswarm = "bench"\n'
    for n, s in enumerate(SHARDS, start=1):
        others = [f'"tcp/10.77.0.{m}:7447"' for m in range(1, 4) if m != n]
        text += (
            f'\n[[shard]]\nname = "{s}"\n'
            f"vehicles = [{{ system_id = {2 * n - 1} }}, {{ system_id = {2 * n} }}]\n"
            f'listen = ["tcp/10.77.0.{n}:7447"]\n'
            f"connect = [{', '.join(others)}]\n"
        )
    path = tmp / "shards.toml"
    path.write_text(text)
    return path


def run_pairs(binary, pairs, duration_s, tmp):
    """`pairs`: (namespace, config, shard or None, run dir). Starts every emulator, then
    every coordinator; waits for the coordinators; stops the emulators."""
    emulators, flights = [], []
    for ns, config, shard, out in pairs:
        extra = ["--shard", shard] if shard else []
        log = open(tmp / f"sitl-{out.name}.log", "w")
        emulators.append(subprocess.Popen(["ip", "netns", "exec", ns, binary, "sitl", "--config", str(config), *extra],
                                          stdout=log, stderr=subprocess.STDOUT))
    time.sleep(1.0)
    for ns, config, shard, out in pairs:
        extra = ["--shard", shard] if shard else []
        log = open(tmp / f"fly-{out.name}.log", "w")
        flights.append(subprocess.Popen(
            ["ip", "netns", "exec", ns, binary, "fly", "--config", str(config), *extra,
             "--duration-s", str(duration_s), "--out", str(out)],
            stdout=log, stderr=subprocess.STDOUT))
    for f in flights:
        f.wait(timeout=duration_s + 120)
    for e in emulators:
        e.terminate()
        e.wait(timeout=30)


def start_of(run):
    """The local time (s) of the run's consensus start, from its events."""
    with open(run / "events.csv", newline="") as f:
        for r in csv.reader(f):
            if "consensus started" in r[-1]:
                adopted = re.search(r"adopted ([0-9.]+) s", r[-1])
                return float(adopted.group(1)) if adopted else float(r[0])
    return None


def position_at(run, sysid, t):
    """Vehicle `sysid`'s (x, y) at local time `t`, from its CSV (linear between rows)."""
    with open(run / f"vehicle-{sysid}.csv", newline="") as f:
        rows = [(float(r["t_s"]), float(r["x_m"]), float(r["y_m"])) for r in csv.DictReader(f)]
    for a, b in zip(rows, rows[1:]):
        if b[0] >= t:
            k = (t - a[0]) / max(b[0] - a[0], 1e-9)
            return (a[1] + k * (b[1] - a[1]), a[2] + k * (b[2] - a[2]))
    return None


def true_formation(runs_of, after_s):
    """Largest distance of a vehicle's p - d from their mean, `after_s` after the start,
    each vehicle taken from the run that flew it (`runs_of`: sysid -> run)."""
    any_run = next(iter(runs_of.values()))
    offsets = [v["offset_enu_m"] for v in json.loads((any_run / "setup.json").read_text())["vehicles"]]
    q = []
    for sysid, d in enumerate(offsets, start=1):
        run = runs_of[sysid]
        p = position_at(run, sysid, start_of(run) + after_s)
        if p is None:
            return None
        q.append((p[0] - d[0], p[1] - d[1]))
    cx, cy = sum(x for x, _ in q) / len(q), sum(y for _, y in q) / len(q)
    return max(math.hypot(x - cx, y - cy) for x, y in q)


def row(name, out):
    s = json.loads((out / "summary.json").read_text())
    p, t = s.get("predicted_final_velocity"), s["timing"]
    pred = f"({p[0]:.3f}, {p[1]:.3f})" if p else "–"
    err = s.get("velocity_error_fraction")
    err = f"{100 * err:.3f} %" if err is not None else "–"
    form = s.get("formation_error_m")
    form = f"{form:.3f} m" if form is not None else "–"
    age, remote = t["state_age"], t.get("remote_state_age") or {}
    hop = (f"{remote['p50_ms']:.1f} / {remote['p99_ms']:.1f}" if remote.get("p50_ms") is not None else "–")
    return (f"| {name} | {pred} | {err} | {form} | {t['late_ticks']} | "
            f"{t['lateness']['p99_ms']:.2f} | {age['p50_ms']:.1f} / {age['p99_ms']:.1f} | {hop} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bin", default=str(ROOT / "target" / "release" / "ringswarm"))
    parser.add_argument("--duration-s", type=float, default=40.0)
    args = parser.parse_args()
    if os.geteuid() != 0:
        sys.exit("network namespaces need root")
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    tmp = Path(tempfile.mkdtemp(prefix="ringswarm-shards-bench-"))
    one, names, made = make_hosts(f"rb{os.getpid() % 10000}")
    try:
        run_pairs(args.bin, [(one, BASE, None, tmp / "one")], args.duration_s, tmp)
        config = shard_config(tmp)
        run_pairs(args.bin, [(names[s], config, s, tmp / f"shard-{s}") for s in SHARDS], args.duration_s, tmp)
    finally:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
    print(f"paper-sim1, {args.duration_s:.0f} s of consensus in real time, {args.bin} at {commit}, "
          f"{os.cpu_count()} cores ({time.strftime('%Y-%m-%d')})\n")
    print("| flight | prediction (m/s) | velocity error | formation at the end (its summary) | late ticks | "
          "tick lateness p99 (ms) | state age p50 / p99 (ms) | other shards' states p50 / p99 (ms) |")
    print("|---|---|---|---|---|---|---|---|")
    print(row("one process", tmp / "one"))
    for s in SHARDS:
        print(row(f"shard {s} of 3, own namespace", tmp / f"shard-{s}"))
    owner = {i: tmp / f"shard-{SHARDS[(i - 1) // 2]}" for i in range(1, 7)}
    checks = [t for t in (10.0, 20.0, 30.0, args.duration_s - 1.0) if t < args.duration_s]
    print("\nformation from each vehicle's own coordinator, seconds after the adopted start:\n")
    print("| flight | " + " | ".join(f"{t:.0f} s" for t in checks) + " |")
    print("|---|" + "---|" * len(checks))
    for name, runs_of in [("one process", {i: tmp / "one" for i in range(1, 7)}), ("3 shards", owner)]:
        cells = [true_formation(runs_of, t) for t in checks]
        print(f"| {name} | " + " | ".join("–" if c is None else f"{c:.3f} m" for c in cells) + " |")
    print(f"\nrun directories: {tmp}")


if __name__ == "__main__":
    main()
