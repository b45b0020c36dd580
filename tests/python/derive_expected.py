"""Prints every expected value used by tests/integration/paper_examples.rs, derived with numpy.

Run: .venv/bin/python tests/python/derive_expected.py
"""

import numpy as np

from ringswarm_ref import brute_force_plan, closed_loop_abscissa, final_velocity, k_min, nonzero_eigenvalues, yu_bound

np.set_printoptions(precision=15)

print("Example 1, m = 4")
print("  k_min", k_min(4))
for k, alpha, beta in [(-0.5, 1, 6), (1.0, 1, 3), (-0.8, 1, 3)]:
    mu = np.sort_complex(np.concatenate([[0], nonzero_eigenvalues(4, k)]))
    print(f"  k = {k}: eigenvalues {np.round(mu, 6)}")
    print(f"  k = {k}: Yu bound {yu_bound(4, k)!r}, abscissa(alpha={alpha}, beta={beta}) {closed_loop_abscissa(4, k, alpha, beta)!r}")

example = [(1, 2), (-1, 3), (-2, 4), (1, 5), (2, 3), (2, 2)]
print("Achievable-velocity example: plan", brute_force_plan(example, (5, -4)))
sim = [(9, 4), (15, 8), (18, -2), (13, 1), (-8, -7), (14, 18)]
print("Second simulation: plan", brute_force_plan(sim, (20, 30)))
print("First simulation: k_min", k_min(3), "Yu bound", yu_bound(3, 5.0), "v_f", final_velocity(sim, 5.0))
