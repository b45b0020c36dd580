"""The `ringswarm` binary against independent numpy computations."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from ringswarm_ref import brute_force_plan, closed_loop_abscissa, final_velocity, k_min, laplacian, yu_bound

ROOT = Path(__file__).resolve().parents[2]
BIN = os.environ.get("RINGSWARM_BIN", str(ROOT / "target" / "debug" / "ringswarm"))


def run(*args):
    out = subprocess.run([BIN, *args], capture_output=True, text=True, timeout=120)
    return out.returncode, out.stdout, out.stderr


CASES = [(1, 0.5, 1.0, 1.0), (2, -1.5, 0.5, 3.0), (3, 5.0, 1.0, 5.0), (4, -0.5, 1.0, 6.0), (4, -0.8, 1.0, 3.0), (7, 0.3, 2.0, 1.0), (12, -0.9, 1.0, 2.0)]


@pytest.mark.parametrize("m,k,alpha,beta", CASES)
def test_analyze_matches_numpy(m, k, alpha, beta):
    code, stdout, stderr = run("analyze", "-m", str(m), "-k", str(k), "--alpha", str(alpha), "--beta", str(beta), "--json")
    assert code in (0, 1), stderr
    got = json.loads(stdout)
    assert got["k_min"] == pytest.approx(k_min(m), abs=1e-12)
    assert got["k_min_numeric"] == pytest.approx(k_min(m), abs=1e-6)
    expected_mu = np.linalg.eigvals(laplacian(m, k))
    got_mu = np.array([complex(re, im) for re, im in got["laplacian_eigenvalues"]])
    for mu in expected_mu:
        assert np.min(np.abs(got_mu - mu)) < 1e-8
    bound = yu_bound(m, k)
    if bound is None:
        assert got["yu_bound"] is None
    else:
        assert got["yu_bound"] == pytest.approx(bound, rel=1e-8)
    abscissa = closed_loop_abscissa(m, k, alpha, beta)
    assert got["closed_loop_abscissa"] == pytest.approx(abscissa, abs=1e-7)
    assert got["stable"] == (bound is not None and abscissa < 0)
    assert code == (0 if got["stable"] else 1)


def test_done_when_figures():
    code, stdout, _ = run("analyze", "--macro-vertices", "4", "--k", "-0.5", "--alpha", "1", "--beta", "6", "--json")
    got = json.loads(stdout)
    assert code == 0 and got["stable"] is True
    assert got["k_min"] == pytest.approx(-1.0, abs=1e-12)
    assert got["yu_bound"] == pytest.approx(5.389, abs=5e-4)
    code, stdout, _ = run("analyze", "--macro-vertices", "4", "--k", "-0.8", "--alpha", "1", "--beta", "3", "--json")
    assert code == 1 and json.loads(stdout)["stable"] is False


RNG = np.random.default_rng(7)
PLAN_CASES = [
    ([(1, 2), (-1, 3), (-2, 4), (1, 5), (2, 3), (2, 2)], (5, -4)),
    ([(9, 4), (15, 8), (18, -2), (13, 1), (-8, -7), (14, 18)], (20, 30)),
] + [
    ([tuple(RNG.uniform(-15, 15, 2).round(2)) for _ in range(2 * m)], tuple(RNG.uniform(-10, 10, 2).round(2)))
    for m in (1, 2, 3, 5)
]


@pytest.mark.parametrize("velocities,target", PLAN_CASES)
def test_plan_matches_brute_force(velocities, target):
    text = ";".join(f"{x},{y}" for x, y in velocities)
    code, stdout, stderr = run("plan", "--initial-velocities", text, "--target", f"{target[0]},{target[1]}", "--json")
    assert code == 0, stderr
    got = json.loads(stdout)
    change, agent, delta, new = brute_force_plan(velocities, target)
    # The grid spacing bounds how close the brute force gets to the exact optimum.
    assert (got["velocity_change"] or 0.0) == pytest.approx(change, abs=1e-4)
    if got["agent"] is not None:
        modified = np.array(velocities, float)
        modified[got["agent"] - 1] = got["new_velocity"]
        assert final_velocity(modified, got["k"]) == pytest.approx(np.array(target), abs=1e-9)
        assert got["k"] >= k_min(len(velocities) // 2) + 0.1 - 1e-12
    assert got["predicted_final_velocity"] == pytest.approx(list(target), abs=1e-9)
