"""fusion.io.truth_table against the dict of dicts it replaced (time -> target id -> state, the
last sample given for a (time, target) winning): the same blocks for any batching of the same
samples, times dropped from the oldest."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.io.truth_table import TruthTable

_sample = st.tuples(st.sampled_from(["a", "b", "c10", "c9", "z"]), st.sampled_from([0, 5, 7, 100]),
                    st.floats(-1e3, 1e3, allow_nan=False))


def _add(table: TruthTable, samples: list[tuple[str, int, float]]) -> None:
    S = np.array([[v, -v] for _, _, v in samples], dtype=np.float64).reshape(-1, 2)
    table.add([k for k, _, _ in samples], [t for _, t, _ in samples], S)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(_sample, max_size=8), max_size=6))
def test_the_blocks_are_the_dict_of_the_samples_in_any_batching(batches: list[list[tuple[str, int, float]]]) -> None:
    table = TruthTable()
    reference: dict[int, dict[str, float]] = {}
    for batch in batches:
        _add(table, batch)
        for k, t, v in batch:
            reference.setdefault(t, {})[k] = v
    assert len(table) == len(reference)
    for t, T in reference.items():
        got = table.at(t)
        assert got is not None
        assert got.ids == sorted(T)
        np.testing.assert_array_equal(got.S, [[T[k], -T[k]] for k in sorted(T)])
    times = [t for b in batches for _, t, _ in b]
    assert table.newest_ns == (max(times) if times else None)
    assert table.at(-1) is None


def test_times_are_dropped_from_the_oldest() -> None:
    table = TruthTable(kept=4)
    for t in range(5):
        _add(table, [("a", t, float(t))])
    assert len(table) == 3 and table.at(0) is None and table.at(1) is None and table.at(2) is not None
    table.forget_before(4)
    assert len(table) == 1 and table.at(4) is not None
    assert table.newest_ns == 4

    following = TruthTable()
    _add(following, [("b", 9, 1.0)])
    following.continue_from(table)
    assert len(following) == 2 and following.newest_ns == 9
    assert following.at(4).ids == ["a"]
