"""Gives each pytest-xdist worker a loopback of its own, so that the tests can run in
parallel.

The tests talk to the emulator on PX4 SITL's fixed ports (offboard 14540 ↔ 14580+i,
ground station 14550 ↔ 18570+i): these ports are what MAVSDK's official examples,
MAVSDK-Python and QGroundControl expect, and the examples hard-code
`udpin://0.0.0.0:14540`, so a test cannot move them to free ports without no longer
testing what a user runs. Instead, with `RINGSWARM_TEST_NETNS=1` (set by
`scripts/test.sh` when namespaces can be made), every xdist worker moves into a new
network namespace before its first test and brings its loopback up: each worker has the
whole port space to itself, and its emulators, clients and mavsdk_servers inherit it.
Without the variable, nothing changes and the tests must run in one process.
"""

import ctypes
import os
import subprocess

CLONE_NEWNET = 0x40000000


def own_loopback():
    """Moves this process (its main thread, and every child it starts later) into a new
    network namespace with its loopback up."""
    before = os.readlink("/proc/self/ns/net")
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"unshare(CLONE_NEWNET) for a worker's own loopback: {os.strerror(err)}")
    after = os.readlink("/proc/self/ns/net")
    if after == before:
        raise RuntimeError(f"unshare(CLONE_NEWNET) returned 0 but the process is still in {before}")
    subprocess.run(["ip", "link", "set", "lo", "up"], check=True)


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "serial: runs after the parallel tests, alone (several coordinators and emulators in "
        "real time: in parallel with the others, the machine's load would be the test)",
    )
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker and os.environ.get("RINGSWARM_TEST_NETNS") == "1":
        own_loopback()
