"""The innovation half of the stacked update gives the update's S, NIS and log-likelihood bit
for bit, and flags the same non-positive-definite S."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.compiled_stack import innovate_stack, update_stack


@pytest.mark.parametrize(("n", "m"), [(4, 2), (5, 2), (6, 3), (4, 1)], ids=["cv-2", "ct-2", "ca-3", "cv-1"])
def test_innovation_equals_the_updates_first_half(n: int, m: int) -> None:
    rng = np.random.default_rng(n * 10 + m)
    N = 300
    A = rng.normal(size=(N, n, n))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(n)
    H = rng.normal(size=(N, m, n))
    B = rng.normal(size=(N, m, m))
    R = B @ np.swapaxes(B, -1, -2) + 0.01 * np.eye(m)
    R[:7] = -np.eye(m) * 1e6  # S not positive definite in the first rows
    X, Y = rng.normal(size=(N, n)), rng.normal(size=(N, m))
    ok_u, _, _, S_u, nis_u, ll_u = update_stack(X, P, Y, H, R)
    ok_i, S_i, nis_i, ll_i = innovate_stack(P, Y, H, R)
    assert not ok_u[:7].any() and ok_u[7:].all()
    np.testing.assert_array_equal(ok_i, ok_u)
    g = ok_u
    assert (S_i[g].tobytes(), nis_i[g].tobytes(), ll_i[g].tobytes()) == (S_u[g].tobytes(), nis_u[g].tobytes(),
                                                                         ll_u[g].tobytes())
