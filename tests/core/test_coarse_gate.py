"""The coarse gate's sweep finds exactly the pairs of the per-axis test, whatever the spread of
the tracks' variances (one wide track among narrow ones included)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.association import coarse_pairs


def brute_force(tp: np.ndarray, tv: np.ndarray, mp: np.ndarray, mv: np.ndarray, k: float
                ) -> tuple[np.ndarray, np.ndarray]:
    d = np.abs(tp[:, None, :] - mp[None, :, :])
    ok = (d * d <= k * k * (tv[:, None, :] + mv[None, :, :])).all(axis=2)
    i, j = np.nonzero(ok)
    s = np.lexsort((i, j))
    return i[s], j[s]


@pytest.mark.parametrize("dim", [1, 2, 3], ids=["1d", "2d", "3d"])
@pytest.mark.parametrize("seed", range(8), ids=[f"seed{s}" for s in range(8)])
def test_sweep_matches_the_per_axis_test(seed: int, dim: int) -> None:
    rng = np.random.default_rng(seed)
    N, M = rng.integers(1, 300), rng.integers(1, 300)
    tp = rng.uniform(-1000, 1000, (N, dim))
    mp = np.concatenate([tp[: M // 2] + rng.normal(0, 5, (min(M // 2, N), dim)),
                         rng.uniform(-1000, 1000, (M - min(M // 2, N), dim))])
    tv = rng.lognormal(2.0, 2.0, (N, dim))  # variances from ~0.1 to ~10^4 m^2
    tv[0] = 1e6  # one very wide track
    mv = rng.lognormal(1.0, 1.0, (mp.shape[0], dim))
    k = float(rng.uniform(1.0, 12.0))
    i, j = coarse_pairs(tp, tv, mp, mv, k=k)
    bi, bj = brute_force(tp, tv, mp, mv, k)
    assert bi.size > 0
    np.testing.assert_array_equal(i, bi)
    np.testing.assert_array_equal(j, bj)


def test_pairs_on_the_gate_edge_are_kept() -> None:
    """A measurement exactly k sigma away on the first axis is in the gate (<=)."""
    tp, tv = np.array([[0.0, 0.0]]), np.array([[4.0, 4.0]])
    mp, mv = np.array([[6.0, 0.0], [6.000001, 0.0]]), np.array([[5.0, 5.0], [5.0, 5.0]])
    i, j = coarse_pairs(tp, tv, mp, mv, k=2.0)
    assert i.tolist() == [0] and j.tolist() == [0]


def test_empty_inputs_give_no_pairs() -> None:
    e = np.zeros((0, 2))
    i, j = coarse_pairs(e, e, np.ones((3, 2)), np.ones((3, 2)), k=3.0)
    assert i.size == j.size == 0
