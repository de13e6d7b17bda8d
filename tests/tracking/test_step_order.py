"""A scan's detections merged with the ones that arrived (fusion.tracking.step_order.merged) are
exactly sorted(stored + arrived, key=seq): the order every scan runs in, equal seqs (two
publishers' epochs) kept stored first, then in arrival order."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.tracking.detection import SEQ, Detection, seqs_of
from fusion.tracking.history import Entry
from fusion.tracking.replay import Gates
from fusion.tracking.step_order import merged, merged_seqs


def _det(seq: int, tag: int) -> Detection:
    return Detection("radar1", 1_000, seq, np.array([float(tag), 0.0]), None, None, tag)


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.lists(st.integers(0, 30), max_size=40), st.lists(st.integers(0, 30), max_size=6))
def test_merged_is_the_stable_sort_of_stored_and_arrived(stored: list[int], arrived: list[int]) -> None:
    old = tuple(sorted((_det(q, k) for k, q in enumerate(stored)), key=SEQ))
    new = [_det(q, 100 + k) for k, q in enumerate(arrived)]
    prev = Entry((1_000, "radar1"), old, None)  # type: ignore[arg-type]
    want = tuple(sorted(old + tuple(new), key=SEQ))
    got = merged(prev, new)
    assert [(d.seq, d.epoch) for d in got] == [(d.seq, d.epoch) for d in want]
    assert [(d.seq, d.epoch) for d in merged(None, new)] == [(d.seq, d.epoch) for d in sorted(new, key=SEQ)]
    assert seqs_of(got).tolist() == [d.seq for d in want]


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(st.lists(st.integers(0, 30), max_size=40), st.lists(st.integers(0, 30), max_size=6), st.booleans())
def test_merged_seqs_are_the_merged_detections_seqs(stored: list[int], arrived: list[int], gated: bool) -> None:
    """The seqs a scan runs with, from the stored scan's gates and the arrived detections, are
    those of `merged`'s detections (equal seqs too), with the gates or without (read from the
    detections then)."""
    old = tuple(sorted((_det(q, k) for k, q in enumerate(stored)), key=SEQ))
    new = [_det(q, 100 + k) for k, q in enumerate(arrived)]
    none = np.zeros(0, dtype=np.int64)
    gates = Gates(none, none, np.zeros((0, 2)), np.zeros((0, 2)), seqs_of(old)) if gated else None
    prev = Entry((1_000, "radar1"), old, None, gates=gates)  # type: ignore[arg-type]
    for p, a in ((prev, new), (prev, None), (None, new)):
        dets = merged(p, a)
        got = merged_seqs(p, a, dets)
        assert got.dtype == np.int64 and got.tolist() == seqs_of(dets).tolist()
