"""The recording's small parts made faster for issue #11 keep what they computed before: the trail's
choice of ellipses (Python floats instead of a numpy call per row), one-concatenate stacking,
label lists built as arrow arrays, and the rotating sink's size check once per flush."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from fusion.io import trail
from fusion.io.arrow_columns import field_arrow
from fusion.io.columns import Column, stack
from fusion.io.recording import RotatingSink

SEED = 20261202


def _pick_numpy(t_ns, pos, r, last):  # the implementation before (a numpy norm per row)
    out = []
    for i in range(len(t_ns)):
        ti = int(t_ns[i])
        gap = trail.SPACING * (last[2] + r[i]) if last is not None else 0.0
        if last is None or (ti > last[0] and float(np.linalg.norm(pos[i] - last[1])) >= gap):
            out.append(i)
            last = (ti, pos[i].copy(), float(r[i]))
    return out, last


@pytest.mark.parametrize("k", [2, 3], ids=["2d", "3d"])
def test_trail_pick_chooses_as_the_numpy_loop_did(k: int) -> None:
    rng = np.random.default_rng(SEED + k)
    last_a = last_b = None
    for chunk in range(5):  # in chunks, as flushes come: the last drawn carries over
        n = 400
        t = chunk * 10**10 + np.sort(rng.integers(0, 10**10, n)).astype(np.int64)
        t[rng.random(n) < 0.1] -= 10**9  # some rows older than the last drawn (revisions)
        pos = np.cumsum(rng.normal(0.0, 1.0, (n, k)), axis=0)
        r = rng.uniform(0.1, 2.0, n)
        a, last_a = trail.pick(t, pos, r, last_a)
        b, last_b = _pick_numpy(t, pos, r, last_b)
        assert a == b, f"seed {SEED + k}"
        assert a, "nothing drawn: the test would not test"
        assert last_a[0] == last_b[0] and np.array_equal(last_a[1], last_b[1]) and last_a[2] == last_b[2]
    assert trail.pick(np.empty(0, np.int64), np.empty((0, k)), np.empty(0), None) == ([], None)
    assert trail.pick(np.empty(0, np.int64), np.empty((0, k)), np.empty(0), last_a) == ([], last_a)


@pytest.mark.parametrize("shape", [(5,), (2, 2), (2, 5)], ids=["vector", "square", "wide"])
def test_stack_equals_np_array(shape: tuple[int, ...]) -> None:
    rng = np.random.default_rng(SEED)
    rows = [rng.normal(size=shape) for _ in range(7)]
    got = stack(rows)
    assert got.dtype == np.float64 and np.array_equal(got, np.array(rows))
    assert stack([], shape).shape == (0, *shape)


def test_arrow_label_lists_concatenate_across_chunks() -> None:
    c = Column("record")
    for flat, lens in ((["a", "b", "c"], [2, 0, 1]), ([], [0]), (["d"], [1])):
        offsets = np.zeros(len(lens) + 1, dtype=np.int32)
        np.cumsum(lens, out=offsets[1:])
        c.extend([0] * len(lens), [0] * len(lens), [0] * len(lens),
                 gated=pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, pa.string())))
    got = field_arrow(c.field("gated"))
    assert got.to_pylist() == [["a", "b"], [], ["c"], [], ["d"]]


def test_rotation_by_size_looks_at_the_file_after_flushes_only(tmp_path: Path) -> None:
    from tests.io.test_recording import maneuver_run

    tr, dets, _ = maneuver_run()
    sink = RotatingSink(tmp_path, prefix="rot", layout=tr.layout, position_indices=tr.position_indices,
                        velocity_indices=tr.velocity_indices, rotate_bytes=1, rotate_s=1e9, flush_interval_s=1e9)
    sink.sink._flush_rows = 10**9
    for d in dets[:20]:  # no flush: the file is not looked at, so no rotation however small rotate_bytes is
        sink.log_step(tr.process([d]))
    assert len(sink.files) == 1
    sink.flush()
    sink.sink.rec.flush()  # the file written (rerun writes in the background)
    sink.log_step(tr.process([dets[20]]))  # after a flush: the size is looked at, past 1 byte
    assert len(sink.files) == 2
    sink.close()


def test_column_times_of_lists_arrays_and_both() -> None:
    """Column.times reads chunks given as lists (add's rows, sealed), as arrays and as other
    sequences, alone or mixed, into int64 arrays with every row in order."""
    rng = np.random.default_rng(SEED)
    want = [rng.integers(0, 2**62, size=k).tolist() for k in (3, 1, 4, 2)]
    flat = [x for part in want for x in part]
    for kinds in (("list",) * 4, ("array",) * 4, ("list", "array", "tuple", "int32")):
        c = Column("record")
        for kind, part in zip(kinds, want, strict=True):
            v: object = {"list": part, "array": np.array(part, dtype=np.int64), "tuple": tuple(part),
                         "int32": np.array([x % 2**31 for x in part], dtype=np.int32)}[kind]
            c.extend(v, v, v, a=list(part))
        exp = [x % 2**31 if kind == "int32" else x for kind, part in zip(kinds, want, strict=True) for x in part]
        for got in c.times():
            assert got.dtype == np.int64 and got.tolist() == exp, kinds
    c = Column("text")
    for x in flat:
        c.add(x, 1, x, text="a", level="INFO")
    t, step, arr = c.times()
    assert t.tolist() == flat and step.tolist() == [1] * len(flat) and arr.tolist() == flat


def test_column_times_of_wide_unsigned_arrays_stay_exact() -> None:
    """Array chunks of other integer types are cast to int64 one by one: a uint64 chunk beside an
    int64 one does not go through float64 (np.concatenate's common type), which would round."""
    big = 2**62 + 1
    c = Column("record")
    c.extend(np.array([big], dtype=np.uint64), np.array([1], dtype=np.uint64), np.array([big], dtype=np.uint64), a=[0])
    c.extend(np.array([5], dtype=np.int64), np.array([2], dtype=np.int64), np.array([5], dtype=np.int64), a=[0])
    t, step, arr = c.times()
    assert t.tolist() == [big, 5] and step.tolist() == [1, 2] and arr.tolist() == [big, 5]
