#!/usr/bin/env python3
"""Writes a coordinator config for a packed block swap: SIDE x SIDE x500s in a square block
`--spacing` metres apart at 50 m, in the air and drifting east at `--drift` m/s, each given
the place mirrored through the block's centre with the places kept in vehicle order
(`[formation] assign = "fixed"`): every path crosses the centre, and the whole block
binds the safety filter (3 m enforced). On MAVLink networks of at most 250 vehicles
(system ids from 1 on each; ports 14600, 14601, ...), so that `ringswarm sitl --config F`
and `ringswarm fly --config F` fly it on one machine.

With `--shards S` the vehicles are split in S contiguous shards (`fly --shard s0` ...
`s{S-1}`), each taking whole networks (one host's shards cannot bind one network's socket)
and watching every vehicle over Zenoh on loopback (tcp/127.0.0.1:7500 + s, each shard
connecting to every shard before it).

`--telemetry-rate-hz 10` boots the emulated PX4s streaming their position and attitude at
10 Hz rather than 50 until the handshake sets each stream: a thousand vehicles at 50 Hz
are 200 000 datagrams a second on a machine that also runs the coordinators.

The safety filter gets `--budget-ms` of each 20 ms control period (`[safety] budget_share`;
2 ms by default, the per-tick time the dense-swarm goal allows; the coordinator's own default
share, 0.2, would give it 4 ms at this rate).

Gains: k = 1, alpha = 1, beta = sqrt(1.25 * Yu's bound) (`ringswarm analyze -m N/2 -k 1`
gives the bound); `--time-scale` as the bandwidth gate asks for the x500 (`fly` says it).

    python3 scripts/block_config.py 32 --yu-bound 51223.26 --time-scale 0.01 > block-1024.toml
"""

import argparse
import math

CONTROL_RATE_HZ = 50.0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("side", type=int, help="vehicles along each side of the block")
    ap.add_argument("--yu-bound", type=float, required=True, help="Yu's bound of the ring (ringswarm analyze)")
    ap.add_argument("--time-scale", type=float, required=True, help="gains.time_scale (the bandwidth gate's)")
    ap.add_argument("--spacing", type=float, default=4.0, help="metres between neighbours")
    ap.add_argument("--drift", type=float, default=1.0, help="east velocity at the start (m/s)")
    ap.add_argument("--duration", type=float, default=60.0, help="seconds of consensus flight")
    ap.add_argument("--shards", type=int, default=1, help="split the block in this many shards (1: none)")
    ap.add_argument("--budget-ms", type=float, default=2.0, help="the safety filter's time per control tick (ms, of 20)")
    ap.add_argument(
        "--telemetry-rate-hz",
        type=float,
        default=None,
        help="[emulator] telemetry_rate_hz: the emulated PX4s' position and attitude rate from boot, "
        "until the handshake sets them (default: the emulator's 50 Hz)",
    )
    a = ap.parse_args()
    n = a.side * a.side
    if a.side < 2 or n % 2:
        raise SystemExit(f"the ring needs an even number of vehicles >= 4, got {a.side} x {a.side}")
    if not (a.spacing > 0 and a.time_scale > 0 and a.yu_bound > 0):
        raise SystemExit("--spacing, --time-scale and --yu-bound must be positive")
    period_ms = 1000.0 / CONTROL_RATE_HZ
    if not (0 < a.budget_ms <= period_ms):
        raise SystemExit(f"--budget-ms must be in (0, {period_ms:g}] (the control period), got {a.budget_ms}")
    if a.shards < 1 or n % a.shards:
        raise SystemExit(f"--shards must divide the {n} vehicles evenly, got {a.shards}")
    # Unsharded: networks of 250 and the rest. Sharded: each shard takes whole networks of
    # equal size, at most 250 vehicles each.
    per_shard = n // a.shards
    per = 250
    if a.shards > 1:
        nets_per_shard = -(-per_shard // 250)
        while per_shard % nets_per_shard:
            nets_per_shard += 1
        per = per_shard // nets_per_shard
    half = 0.5 * a.spacing * (a.side - 1)
    starts = [(a.spacing * (i % a.side) - half, a.spacing * (i // a.side) - half) for i in range(n)]
    beta = math.sqrt(1.25 * a.yu_bound)
    out = [
        f"# {n} x500s in a {a.side} x {a.side} block {a.spacing} m apart, drifting east at {a.drift} m/s,",
        "# each sent to its start mirrored through the centre, places in vehicle order.",
        f"# Written by scripts/block_config.py {a.side} --yu-bound {a.yu_bound} --time-scale {a.time_scale}.",
        "# Frames: ENU about the common reference (x east, y north, z up), metres and m/s.",
        "",
        "[swarm]",
        f"control_rate_hz = {CONTROL_RATE_HZ}",
        "attitude_rate_hz = 10.0",
        f"duration_s = {a.duration}",
        "link_timeout_ms = 1500",
        'end = "hold"',
        "handshake_timeout_s = 120.0",
        "",
        "[gains]",
        "k = 1.0",
        "alpha = 1.0",
        f"beta = {beta:.3f}",
        "k_pz = 1.0",
        "k_vz = 4.0",
        f"time_scale = {a.time_scale}",
        "",
        "[formation]",
        'kind = "offsets"',
        "offsets_m = [" + ", ".join(f"[{-x:.3f}, {-y:.3f}]" for x, y in starts) + "]",
        "altitude_m = 50.0",
        'assign = "fixed"',
        "",
        "[envelope]",
        "max_tilt_deg = 35.0",
        "min_thrust = 0.1",
        "max_thrust = 0.9",
        'saturation = "conserve"',
        "",
        "[safety]",
        "horizontal_m = 3.0",
        f"budget_share = {a.budget_ms / period_ms:g}",
        "",
        "[emulator]",
        "ground_below_m = 100.0",
    ]
    if a.telemetry_rate_hz is not None:
        if not (0.0 < a.telemetry_rate_hz <= 1000.0):
            raise SystemExit(f"--telemetry-rate-hz must be in (0, 1000], got {a.telemetry_rate_hz}")
        out.append(f"telemetry_rate_hz = {a.telemetry_rate_hz:g}")
    out.append("")
    if a.shards > 1:
        out += ["[distributed]", 'swarm = "block"', 'watch = "all"', ""]
        for s in range(a.shards):
            out += [
                "[[shard]]",
                f'name = "s{s}"',
                "vehicles = ["
                + ", ".join(f'{{ system_id = {i % per + 1}, network = "n{i // per}" }}' for i in range(s * per_shard, (s + 1) * per_shard))
                + "]",
                f'listen = ["tcp/127.0.0.1:{7500 + s}"]',
                "connect = [" + ", ".join(f'"tcp/127.0.0.1:{7500 + t}"' for t in range(s)) + "]",
                "",
            ]
    for j in range((n + per - 1) // per):
        out += ["[[network]]", f'name = "n{j}"', f'bind = "0.0.0.0:{14600 + j}"', ""]
    for i, (x, y) in enumerate(starts):
        out += [
            "[[vehicle]]",
            f"system_id = {i % per + 1}",
            f'network = "n{i // per}"',
            'profile = "x500"',
            "mass_kg = 2.0",
            "hover_throttle = 0.5",
            "drag_per_s = 0.1",
            f"start_enu_m = [{x:.3f}, {y:.3f}, 50.0]",
            f"start_velocity_enu_mps = [{a.drift}, 0.0, 0.0]",
            "in_air = true",
            "",
        ]
    print("\n".join(out))


if __name__ == "__main__":
    main()
