"""derive.match_truth against a plain per-estimate reference: the nearest true target at the
estimate's time (ties to the lower id), kept when within MATCH_D2 in squared Mahalanobis
distance of the position block; times with few targets (padded distances) and many (k-d tree)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.io.derive import MATCH_D2, match_truth
from fusion.io.truth_table import TruthTable

PI = [0, 2]


def _reference(t: np.ndarray, X: np.ndarray, P: np.ndarray, truth: dict) -> tuple[list, list, list]:
    idx, states, names = [], [], []
    for i in range(len(t)):
        T = truth.get(int(t[i]))
        if not T:
            continue
        ids = sorted(T)
        d = [float(np.sum((X[i, PI] - T[k][PI]) ** 2)) for k in ids]
        k = ids[int(np.argmin(d))]
        dp = X[i, PI] - T[k][PI]
        if dp @ np.linalg.solve(P[i][np.ix_(PI, PI)], dp) < MATCH_D2:
            idx.append(i)
            states.append(T[k])
            names.append(k)
    return idx, states, names


@pytest.mark.parametrize("n_targets", [1, 5, 16, 17, 40], ids=lambda n: f"{n}-targets")
def test_match_truth_is_the_nearest_within_the_gate(n_targets: int) -> None:
    rng = np.random.default_rng(20 + n_targets)
    times = [1_000, 2_000, 3_000]
    truth = {tt: {f"t{j:02d}": rng.normal(0.0, 200.0, 4) for j in range(n_targets)} for tt in times[:2]}
    rows = []
    for tt in times:  # the last time has no truth: nothing matched there
        for k in truth.get(tt, truth[times[0]]).values():
            rows.append((tt, k + rng.normal(0.0, [3.0, 1.0, 3.0, 1.0])))
        rows.append((tt, rng.normal(0.0, 200.0, 4)))  # clutter-like: far from every target, mostly
    order = rng.permutation(len(rows))
    t = np.array([rows[i][0] for i in order], dtype=np.int64)
    X = np.array([rows[i][1] for i in order])
    P = np.stack([np.diag(rng.uniform(1.0, 30.0, 4)) for _ in order])
    table = TruthTable()
    samples = [(k, tt, s) for tt, T in truth.items() for k, s in reversed(T.items())]  # ids out of order
    table.add([k for k, _, _ in samples], [tt for _, tt, _ in samples], np.stack([s for _, _, s in samples]))
    idx, states, names = match_truth(t, X, P, table, PI)
    r_idx, r_states, r_names = _reference(t, X, P, truth)
    assert idx.tolist() == r_idx, f"seed {20 + n_targets}"
    assert names == r_names
    np.testing.assert_array_equal(states, np.array(r_states).reshape(-1, 4))
    assert len(r_idx) >= 2 * n_targets * 0.9  # the test matches most true targets at both times
