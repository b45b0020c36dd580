"""What the tests of `fly --shard` share: reading a run directory's events while the
flight goes on, waiting on them, and stopping a process as an operator would."""

import csv
import re
import signal
import subprocess
import time

import pytest

START = re.compile(r"consensus started at the adopted ([0-9.]+) s \(swarm clock (\d+) µs\)")
PREDICTED = re.compile(r"predicted final velocity \((-?[0-9.]+), (-?[0-9.]+)\) m/s")


def events(run):
    """The rows of `run`/events.csv so far (none before it exists)."""
    path = run / "events.csv"
    if not path.exists():
        return []
    with open(path, newline="") as f:
        return list(csv.reader(f))[1:]


def wait_for(predicate, timeout_s, what):
    """`predicate()` once it is truthy, polled every 200 ms; fails after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = predicate()
        if found:
            return found
        time.sleep(0.2)
    pytest.fail(f"not within {timeout_s} s: {what}")


def stop(process):
    """SIGTERM twice (land, then stop at once), then SIGKILL if it has not exited."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        time.sleep(0.3)
        process.send_signal(signal.SIGTERM)
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def starts_of(run):
    """Each consensus start logged: (own clock s, swarm clock µs)."""
    return [(float(m.group(1)), int(m.group(2))) for m in (START.search(r[-1]) for r in events(run)) if m]


def predictions_of(run):
    """Each prediction made from every shard's sums: (vx, vy) m/s as printed."""
    return [
        (float(m.group(1)), float(m.group(2)))
        for m in (PREDICTED.search(r[-1]) for r in events(run) if "every shard's sum" in r[-1])
        if m
    ]
