"""Independent reference computations with numpy (no code shared with the Rust crate).

The ring digraph is built from the paper's description: odd agent 2i-1 (1-based) listens
to its partner 2i with weight k and to agent 2i-2 (wrapping to N) with weight 1; even
agent 2i listens to 2i-1 with weight 1. L is the out-Laplacian of those weights.
"""

import numpy as np


def laplacian(m, k):
    n = 2 * m
    adjacency = np.zeros((n, n))
    for i in range(m):
        odd, even = 2 * i, 2 * i + 1  # 0-based
        previous = (odd - 1) % n
        adjacency[odd, even] += k
        adjacency[odd, previous] += 1.0
        adjacency[even, odd] += 1.0
    return np.diag(adjacency.sum(axis=1)) - adjacency


def k_min(m):
    return -2.0 if m == 1 else -2.0 + np.sqrt(2.0) * np.cos(np.pi / m)


def nonzero_eigenvalues(m, k):
    mu = np.linalg.eigvals(laplacian(m, k))
    return mu[np.argsort(np.abs(mu))][1:]


def yu_bound(m, k):
    mu = nonzero_eigenvalues(m, k)
    if np.any(mu.real <= 0):
        return None
    return float(np.max(mu.imag**2 / (mu.real * np.abs(mu) ** 2)))


def closed_loop_abscissa(m, k, alpha, beta):
    lap = laplacian(m, k)
    n = lap.shape[0]
    a = np.block([[np.zeros((n, n)), np.eye(n)], [-alpha * lap, -beta * lap]])
    s = np.linalg.eigvals(a)
    return float(np.max(s[np.argsort(np.abs(s))][2:].real))


def weights(n, k):
    return np.array([1.0 if i % 2 == 0 else 1.0 + k for i in range(n)])


def final_velocity(velocities, k):
    v = np.asarray(velocities, float)
    w = weights(len(v), k)
    return w @ v / w.sum()


def brute_force_plan(velocities, target, margin=0.1, k_max=10.0, points=2_000_001):
    """Least one-agent change of initial velocity that makes the swarm reach `target`,
    searched over a dense grid of delta = 1 + k for every agent. Ties in the change are
    broken by the slower new velocity. Returns (change, agent0, delta, new_velocity)."""
    v = np.asarray(velocities, float)
    target = np.asarray(target, float)
    n = len(v)
    deltas = np.linspace(1.0 + k_min(n // 2) + margin, 1.0 + k_max, points)
    best = None
    for j in range(n):
        w = np.where(np.arange(n)[:, None] % 2 == 0, 1.0, deltas[None, :])  # n x grid
        others = (w[:, :, None] * v[:, None, :]).sum(axis=0) - w[j][:, None] * v[j][None, :]
        ok = np.abs(w[j]) > 1e-12
        new = (target[None, :] * w.sum(axis=0)[:, None] - others) / np.where(ok, w[j], 1.0)[:, None]
        change = np.linalg.norm(new - v[j][None, :], axis=1)
        change[~ok] = np.inf
        i = int(np.argmin(change))
        candidate = (float(change[i]), float(np.linalg.norm(new[i])), j, float(deltas[i]), new[i])
        if best is None or candidate[0] < best[0] - 1e-6 or (
            abs(candidate[0] - best[0]) <= 1e-6 and candidate[1] < best[1] - 1e-9
        ):
            best = candidate
    change, _, agent, delta, new = best
    return change, agent, delta, new
