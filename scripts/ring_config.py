#!/usr/bin/env python3
"""Writes a coordinator config for a large ring: N ideal quadrotors (N even) hovering on a
circle at 50 m, spaced `--spacing` metres apart, on ceil(N/250) MAVLink networks (system
ids 1..250 on each, or 1..--per-network; ports 14600, 14601, ...), so that `ringswarm sitl --config F` and
`ringswarm fly --config F` fly it on one machine.

Velocities: every vehicle 1 m/s east, odd agents (paper numbering) 0.2 m/s south, even
ones 0.2 m/s north. With k = 1, w = (1, 2, 1, 2, ...): the predicted final velocity is
(1, 0.2/3) m/s east/north.

Gains: Yu's bound grows as m^2 (docs/math.md); beta = sqrt(1.25 * bound) with alpha = 1,
flown at the time scale that keeps the fastest mode within the bandwidth gate for the
ideal frame at 50 Hz (omega * T <= 0.5). `ringswarm analyze -m M -k 1` gives the bound.

    python3 scripts/ring_config.py 1000 --yu-bound 48850.26 > ring-1000.toml
"""

import argparse
import math


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("vehicles", type=int)
    ap.add_argument("--yu-bound", type=float, required=True, help="Yu's bound of the ring (ringswarm analyze)")
    ap.add_argument("--spacing", type=float, default=5.0, help="metres between neighbours")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds of consensus flight")
    ap.add_argument("--rate", type=float, default=50.0, help="control rate (Hz)")
    ap.add_argument("--port", type=int, default=14600, help="first network's port")
    ap.add_argument("--per-network", type=int, default=250, help="vehicles per network (system ids 1..this on each)")
    a = ap.parse_args()
    n = a.vehicles
    if n < 2 or n % 2:
        raise SystemExit(f"the ring needs an even number of vehicles >= 2, got {n}")
    beta = math.sqrt(1.25 * a.yu_bound)
    fastest = 3.0 * beta  # |s| of the fastest mode is about beta * max|mu| = 3 beta (k = 1)
    time_scale = min(1.0, 0.45 * a.rate / fastest)
    radius = a.spacing * n / (2.0 * math.pi)
    per = a.per_network
    if not 1 <= per <= 250:
        raise SystemExit(f"--per-network must be 1..250 (PX4's system ids), got {per}")
    networks = (n + per - 1) // per
    out = [
        f"# {n} ideal quadrotors (m = {n // 2}) on a circle of radius {radius:.1f} m at 50 m,",
        f"# {networks} MAVLink network(s). Written by scripts/ring_config.py {n} --yu-bound {a.yu_bound}.",
        "# Frames: ENU about the common reference (x east, y north, z up), metres and m/s.",
        "",
        "[swarm]",
        f"control_rate_hz = {a.rate}",
        f"attitude_rate_hz = {min(10.0, a.rate)}",
        f"duration_s = {a.duration}",
        "link_timeout_ms = 1500",
        'end = "hold"',
        "",
        "[gains]",
        "k = 1.0",
        "alpha = 1.0",
        f"beta = {beta:.3f}",
        "k_pz = 1.0",
        "k_vz = 4.0",
        f"time_scale = {time_scale:.5f}",
        "",
        "[formation]",
        'kind = "polygon"',
        f"radius_m = {radius:.3f}",
        "altitude_m = 50.0",
        "",
        "[envelope]",
        "max_tilt_deg = 45.0",
        "min_thrust = 0.1",
        "max_thrust = 0.95",
        'saturation = "conserve"',
        "",
        "[emulator]",
        "ground_below_m = 100.0",
        "",
    ]
    for j in range(networks):
        out += ["[[network]]", f'name = "n{j}"', f'bind = "0.0.0.0:{a.port + j}"', ""]
    for i in range(n):
        angle = 2.0 * math.pi * i / n
        north = -0.2 if i % 2 == 0 else 0.2
        out += [
            "[[vehicle]]",
            f"system_id = {i % per + 1}",
            f'network = "n{i // per}"',
            'profile = "ideal"',
            "mass_kg = 1.0",
            "hover_throttle = 0.2",
            f"start_enu_m = [{radius * math.cos(angle):.3f}, {radius * math.sin(angle):.3f}, 50.0]",
            f"start_velocity_enu_mps = [1.0, {north}, 0.0]",
            "in_air = true",
            "",
        ]
    print("\n".join(out))


if __name__ == "__main__":
    main()
