"""LatencyTracker.add_many and SeqGaps.add_many (the pipeline's once-per-batch calls) leave the
statistics exactly as add of each value in order does."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.io.gaps import SeqGaps
from fusion.io.latency import LatencyTracker


@pytest.mark.parametrize("seed", range(4))
def test_latency_add_many_is_add_of_each(seed: int) -> None:
    rng = np.random.default_rng(seed)
    one, many = LatencyTracker(window=64), LatencyTracker(window=64)
    for _ in range(40):
        s = str(rng.choice(["a", "b"]))
        xs = [int(x) for x in rng.integers(-10**9, 10**10, int(rng.choice([0, 1, 5, 63, 64, 65, 200])))]
        for x in xs:
            one.add(s, x)
        many.add_many(s, xs)
        assert one.stats() == many.stats()
        for k in one._ring:  # the rings themselves, value for value
            n = min(one._n[k], one.window)
            assert one._ring[k][:n].tobytes() == many._ring[k][:n].tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_gaps_add_many_is_add_of_each(seed: int) -> None:
    rng = np.random.default_rng(seed)
    one, many = SeqGaps(max_intervals=8, max_epochs=2), SeqGaps(max_intervals=8, max_epochs=2)
    seq = {0: 0, 1: 0, 2: 0}
    for _ in range(60):
        s = str(rng.choice(["a", "b"]))
        pairs = []
        for _ in range(int(rng.integers(0, 30))):
            e = int(rng.choice([0, 1, 2], p=[0.8, 0.15, 0.05]))
            seq[e] += int(rng.choice([1, 1, 1, 2, 5, -3]))  # mostly in order; gaps, late ones
            pairs.append((e, max(seq[e], 0)))
        for e, q in pairs:
            one.add(s, e, q)
        many.add_many(s, [e for e, _ in pairs], [q for _, q in pairs])
        assert one.report() == many.report()
