"""fusion.io.arrow_columns builds the same arrow columns as Rerun's archetype builders (the way
the recording wrote every entity before: `rr.Scalars.columns(...).partition(...)`,
`rr.Points3D.columns`, ..., `rr.TimeColumn`): the same component descriptors, arrow types,
values and row offsets, for every kind of Column the sink writes, built the ways the sink builds
them (rows added one by one, blocks extended, ragged points, strips of one or of several
lengths). And a file written with them reads back with the same values."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun as rr

from fusion.io.arrow_columns import components, field_arrow, record_block, time_index
from fusion.io.columns import Column, Ragged
from fusion.io.rrd_read import read_chunks

SEED = 20261206


def _reference(c: Column) -> list:
    """The columns as Rerun's archetype builders make them (the sink's code before)."""
    n = len(c)
    if c.kind == "scalars":
        v = np.asarray(c.field("v"), dtype=np.float64).reshape(n, c.style["width"])
        return list(rr.Scalars.columns(scalars=v.ravel()).partition(np.full(n, c.style["width"])))
    if c.kind == "points":
        pos, lens = c.ragged("p", 3, np.float64)
        cols = c.ragged("rgba", 4, np.uint8)[0] if c.has("rgba") else \
            np.tile(np.array(c.style["rgba"], np.uint8), (len(pos), 1))
        kw = {"positions": pos, "colors": cols, "radii": np.full(len(pos), c.style.get("radius", -2.0), np.float32)}
        if c.has("label"):
            kw["labels"] = [lab for labs in c.field("label") for lab in labs]
            kw["show_labels"] = np.full(len(pos), c.style.get("show_labels", True))
        return list(rr.Points3D.columns(**kw).partition(lens))
    if c.kind == "strips":
        strips = c.field("s")
        arr = np.asarray(strips, np.float32) if isinstance(strips, np.ndarray) or len(
            {np.shape(x) for x in strips}) == 1 else [np.asarray(x, np.float32) for x in strips]
        return list(rr.LineStrips3D.columns(strips=arr, colors=np.tile(np.array(c.style["rgba"], np.uint8), (n, 1)),
                                            radii=np.full(n, c.style.get("radius", -1.0), np.float32)))
    if c.kind == "ellipsoids":
        return list(rr.Ellipsoids3D.columns(
            centers=np.asarray(c.field("c")), half_sizes=np.asarray(c.field("h")), quaternions=np.asarray(c.field("q")),
            colors=np.tile(np.array(c.style["rgba"], np.uint8), (n, 1)),
            line_radii=np.full(n, c.style.get("radius", -1.0), np.float32)))
    if c.kind == "text":
        return list(rr.TextLog.columns(text=c.field("text"), level=c.field("level")))
    fields = {k: field_arrow(c.field(k)) for k in c.names()}
    fields.update({k: record_block(v) for k, v in c.blocks.items()})
    return list(rr.AnyValues.columns(**fields))


def _assert_same(got: list, want: list) -> None:
    key = {str(w.component_descriptor()): w for w in want}
    assert sorted(str(g.component_descriptor()) for g in got) == sorted(key)
    for g in got:
        w = key[str(g.component_descriptor())]
        assert g.component_descriptor() == w.component_descriptor()
        a, b = g.as_arrow_array(), w.as_arrow_array()
        assert a.type == b.type, (str(g.component_descriptor()), a.type, b.type)
        # the same values (NaN as NaN: arrow's equals counts NaN as unequal) and partition
        assert a.equals(b) or repr(a.to_pylist()) == repr(b.to_pylist()), str(g.component_descriptor())


def _columns(rng: np.random.Generator) -> list[Column]:
    out = []
    sc = Column("scalars", width=3, names=["a", "b", "c"])
    sc.extend(np.arange(5), np.arange(5), np.arange(5), v=rng.normal(size=(5, 3)))
    for k in range(3):
        sc.add(10 + k, 10 + k, 10 + k, v=rng.normal(size=3).tolist())
    out.append(sc)
    pts = Column("points", rgba=(1, 2, 3, 255), radius=-1.5)
    pts.extend([1, 2], [1, 2], [1, 2], p=rng.normal(size=(2, 4, 3)))
    lens = np.array([3, 0, 2])
    pts.extend([3, 4, 5], [3, 4, 5], [3, 4, 5], p=Ragged(rng.normal(size=(5, 3)), lens))
    out.append(pts)
    lab = Column("points", radius=-2.0)
    lab.extend([1, 2], [1, 2], [1, 2], p=Ragged(rng.normal(size=(3, 3)), [1, 2]),
               rgba=Ragged(rng.integers(0, 256, (3, 4)).astype(np.uint8), [1, 2]), label=[["a"], ["b", "c"]])
    lab.add(3, 3, 3, p=rng.normal(size=(1, 3)), rgba=np.array([[9, 8, 7, 6]], np.uint8), label=["d"])
    out.append(lab)
    same = Column("strips", rgba=(10, 20, 30, 40), radius=-0.5)
    same.extend([1, 2], [1, 2], [1, 2], s=rng.normal(size=(2, 8, 3)).astype(np.float32))
    out.append(same)
    mixed = Column("strips", rgba=(10, 20, 30, 40))
    mixed.add(1, 1, 1, s=rng.normal(size=(8, 3)))
    mixed.add(2, 2, 2, s=rng.normal(size=(5, 3)))
    out.append(mixed)
    ell = Column("ellipsoids", rgba=(5, 6, 7, 8), radius=-1.0)
    q = rng.normal(size=(3, 4))
    ell.extend([1, 2, 3], [1, 2, 3], [1, 2, 3], c=rng.normal(size=(3, 3)), h=rng.uniform(1, 2, (3, 3)),
               q=q / np.linalg.norm(q, axis=1, keepdims=True))
    out.append(ell)
    text = Column("text")
    text.add(1, 1, 1, text="track a born", level="INFO")
    text.add(2, 2, 2, text="refused radar1#3: stale", level="WARN")
    out.append(text)
    rec = Column("record")
    rec.extend([1, 2], [1, 2], [1, 2], blocks={"x": rng.normal(size=(2, 4))}, track=[7, 8], label=["a", "b"],
               nis=np.array([1.0, np.nan]), gated=pa.array([["a"], []], type=pa.list_(pa.string())))
    rec.extend([3], [3], [3], blocks={"x": rng.normal(size=(1, 4))}, track=[9], label=["c"], nis=np.array([2.0]),
               gated=pa.array([["c", "d"]], type=pa.list_(pa.string())))
    out.append(rec)
    vec = Column("record")
    vec.add(1, 1, 1, target="t1", x=rng.normal(size=5))
    vec.add(2, 2, 2, target="t2", x=rng.normal(size=5))
    out.append(vec)
    return out


@pytest.mark.parametrize("k", range(9), ids=["scalars", "points", "labelled-points", "strips", "mixed-strips",
                                              "ellipsoids", "text", "record", "record-vectors"])
def test_components_equal_rerun_archetype_columns(k: int) -> None:
    c = _columns(np.random.default_rng(SEED + k))[k]
    want = _reference(c)
    c2 = _columns(np.random.default_rng(SEED + k))[k]  # a fresh copy: fields are read once each way
    _assert_same(components(c2), want)


@pytest.mark.parametrize("epoch", [True, False, None], ids=["timestamp", "duration", "sequence"])
def test_time_index_equals_rerun_time_column(epoch: bool | None) -> None:
    t = np.array([0, 5, 1_733_000_000_000_000_000, 7], dtype=np.int64)
    got = time_index("t", t, epoch=epoch)
    if epoch is None:
        want = rr.TimeColumn("t", sequence=t)
    elif epoch:
        want = rr.TimeColumn("t", timestamp=t.astype("datetime64[ns]"))
    else:
        want = rr.TimeColumn("t", duration=t.astype("timedelta64[ns]"))
    assert got.timeline_name() == want.timeline_name()
    a, b = got.as_arrow_array(), want.as_arrow_array()
    assert a.type == b.type and a.equals(b)
    assert time_index("t", t.tolist(), epoch=epoch).as_arrow_array().equals(b)  # a list
    wide = np.stack([t, -t], axis=1)
    assert time_index("t", wide[:, 0], epoch=epoch).as_arrow_array().equals(b)  # a strided view
    before = a.cast(pa.int64()).to_pylist()
    t[0] = 99  # the caller's array changed after the call: not the arrow array's values
    assert a.cast(pa.int64()).to_pylist() == before  # (rr.TimeColumn's sequence would follow it: its buffer is t's)


def test_a_file_written_with_them_reads_back(tmp_path: Path) -> None:
    """Scalars and points through send_columns to a file, read back by Rerun's dataframe API."""
    path = tmp_path / "c.rrd"
    rec = rr.RecordingStream("fusion-test", recording_id="arrow-columns")
    rec.save(str(path))
    rng = np.random.default_rng(SEED)
    sc = Column("scalars", width=2)
    v = rng.normal(size=(6, 2))
    t = np.arange(6, dtype=np.int64) * 1_000_000_000
    sc.extend(t, np.arange(6), t, v=v)
    idx = [time_index("t", t, epoch=False), time_index("step", np.arange(6), epoch=None)]
    rec.send_columns("tracks/a/v", indexes=idx, columns=components(sc), strict=True)
    pts = Column("points", rgba=(1, 2, 3, 255))
    p = rng.normal(size=(6, 1, 3))
    pts.extend(t, np.arange(6), t, p=p)
    rec.send_columns("world/p", indexes=[time_index("t", t, epoch=False)], columns=components(pts), strict=True)
    rec.flush()
    rec.disconnect()
    got: dict[str, list] = {}
    for ch in read_chunks(path)[0]:
        b = ch.to_record_batch()
        for name in b.schema.names:
            if ch.entity_path in ("/tracks/a/v", "/world/p") and name in ("Scalars:scalars", "Points3D:positions"):
                got.setdefault(name, []).extend(b.column(name).to_pylist())
    assert np.array_equal(np.array(got["Scalars:scalars"]), v)
    assert np.array_equal(np.array(got["Points3D:positions"]).reshape(6, 3), p.reshape(6, 3).astype(np.float32))
