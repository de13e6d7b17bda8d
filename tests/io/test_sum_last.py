"""derive.sum_last gives np.sum(a, axis=-1) to the bit (match_truth's nearest target depends on
it), for the 1-3 position components it is used for and past numpy's 8-component switch."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.io.derive import sum_last


@pytest.mark.parametrize("k", [1, 2, 3, 4, 7, 8, 9], ids=lambda k: f"k{k}")
def test_sum_last_is_numpys_sum(k: int) -> None:
    seed = 20261206 + k
    rng = np.random.default_rng(seed)
    a = np.square(rng.normal(size=(5000, 12, k)) * rng.lognormal(sigma=3.0, size=(5000, 12, k)) * 1e3)
    assert np.array_equal(sum_last(a), np.sum(a, axis=2)), f"seed {seed}"
