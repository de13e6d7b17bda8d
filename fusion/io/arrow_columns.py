"""A pending Column (fusion.io.columns) as the arrow columns of one `send_columns` call, built
from its numpy blocks directly.

Rerun's archetype builders (`rr.Scalars.columns(...).partition(...)`, `rr.TimeColumn`, ...)
convert every field through their Python component classes. Built with them, writing one
entity of scalars (fusion.io.rerun_file.RerunFile.send: 300 rows of 2 values, or 40 of 3, with
its three time columns) took 150-180 us of thread CPU; with the arrays made once, as numpy, and
wrapped as the same arrow arrays, 80-90 us (2026-12-06; ~50 us of it Rerun's call). The result
is the same data with the same types and component descriptors as the archetype builders give
(tests/io/test_arrow_columns.py compares them for every kind the sink writes): the types and
descriptors are taken from Rerun's own builders, once, on a one-row example
(`_proto`), so they follow Rerun's schema rather than a copy of it.

What goes through Rerun's public column interfaces: `rr.ComponentColumn` (its descriptor and
`as_arrow_array`, a list of the component's items per row: a subclass that is given that list
array whole, `_list_column`) and `rr.TimeColumnLike` (anything with `timeline_name` and
`as_arrow_array`).

Kinds (Column.kind -> archetype): scalars -> Scalars (every row `width` values), points ->
Points3D (rows of varying numbers of points, per-point colours and labels), strips ->
LineStrips3D (one strip a row), ellipsoids -> Ellipsoids3D, text -> TextLog, record -> AnyValues
(one component per field, named by it: `field_arrow` and `record_block` make its arrays).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from fusion.core.checks import Array
from fusion.io.columns import Column


class TimeIndex:
    """A time column (rr.TimeColumnLike): a timeline's name and its arrow values."""

    __slots__ = ("array", "name")

    def __init__(self, name: str, array: pa.Array) -> None:
        self.name, self.array = name, array

    def timeline_name(self) -> str:
        return self.name

    def as_arrow_array(self) -> pa.Array:
        return self.array


_TIME_TYPES = {None: pa.int64(), True: pa.timestamp("ns"), False: pa.duration("ns")}


def time_index(name: str, t_ns: Sequence[int] | Array, *, epoch: bool | None) -> TimeIndex:
    """A timeline of integer ns: timestamps (epoch), durations from the stream's start (False),
    or a sequence (None: the step counter). The same arrow values as rr.TimeColumn's, on the
    int64 array's own buffer: pa.array of the datetime64 copy cost 7.6 us for 20 rows and 22 us
    for 2 000, this 2.5 us whatever the rows (2026-12-08), and a record flush sends three per
    entity. The buffer is a copy of its own: Rerun may hold it after the call, and the caller's
    array is the caller's."""
    a = np.array(t_ns, dtype=np.int64)  # a new C-contiguous array
    return TimeIndex(name, pa.Array.from_buffers(_TIME_TYPES[epoch], len(a), [None, pa.py_buffer(a)]))


@functools.cache
def _proto(kind: str) -> dict[str, tuple[Any, pa.DataType]]:
    """Each field's component descriptor and batch type, as Rerun's builder makes them for one row."""
    import rerun as rr

    one = {
        "scalars": lambda: rr.Scalars.columns(scalars=np.zeros(1)),
        "points": lambda: rr.Points3D.columns(positions=np.zeros((1, 3)), colors=np.zeros((1, 4), np.uint8),
                                              radii=np.zeros(1, np.float32), labels=["a"],
                                              show_labels=np.ones(1, bool)),
        "strips": lambda: rr.LineStrips3D.columns(strips=np.zeros((1, 2, 3), np.float32),
                                                  colors=np.zeros((1, 4), np.uint8), radii=np.zeros(1, np.float32)),
        "ellipsoids": lambda: rr.Ellipsoids3D.columns(
            centers=np.zeros((1, 3)), half_sizes=np.ones((1, 3)), quaternions=np.array([[0.0, 0.0, 0.0, 1.0]]),
            colors=np.zeros((1, 4), np.uint8), line_radii=np.zeros(1, np.float32)),
        "text": lambda: rr.TextLog.columns(text=["a"], level=["INFO"]),
    }[kind]()
    out = {}
    for col in one:
        d = col.component_descriptor()
        out[d.component.rpartition(":")[2]] = (d, col.component_batch.as_arrow_array().type)  # "Points3D:radii"
    return out


@functools.cache
def _list_column() -> type:
    """rr.ComponentColumn with its list array (a list of the batch's items per row) given whole:
    what Rerun's makes of a batch and its offsets in `as_arrow_array` (pa.ListArray.from_arrays),
    made once by the caller, and for a record's fields of lists (vectors, label lists) their own
    list arrays as they are (Rerun's took them apart into values and offsets and built them
    again). A record of 14 fields and 150 rows: components 343 us and the whole send 809-1 019,
    against 456 and 1 086 through Rerun's ComponentColumn (2026-12-08, a slow hour)."""
    import rerun as rr

    class ListColumn(rr.ComponentColumn):  # type: ignore[misc]
        def __init__(self, descriptor: Any, array: pa.Array) -> None:  # what ComponentColumn keeps
            self.descriptor = descriptor
            self.array = array

        def as_arrow_array(self) -> pa.Array:
            return self.array

    return ListColumn


@functools.cache
def _descriptor(name: str) -> Any:
    """A record field's component descriptor (rr.AnyValues': the field's name), made once."""
    import rerun as rr

    return rr.ComponentDescriptor(name)


def _col(kind: str, name: str, values: pa.Array, offsets: Array) -> Any:
    desc, _ = _proto(kind)[name]
    return _list_column()(desc, pa.ListArray.from_arrays(offsets, values))


def _unit(n: int) -> Array:
    return np.arange(n + 1, dtype=np.int32)


def _vectors(kind: str, name: str, v: Array, width: int) -> pa.Array:
    """(n, width) values as the field's fixed-size-list batch (its item type, e.g. float32)."""
    t = _proto(kind)[name][1]
    flat = np.ascontiguousarray(v, dtype=t.value_type.to_pandas_dtype()).reshape(-1)
    return pa.FixedSizeListArray.from_arrays(pa.array(flat), type=t)


def _rgba(rgba: Array) -> pa.Array:
    """(n, 4) uint8 colours as Rerun's packed 0xRRGGBBAA uint32."""
    c = np.asarray(rgba, dtype=np.uint32).reshape(-1, 4)
    return pa.array((c[:, 0] << 24) | (c[:, 1] << 16) | (c[:, 2] << 8) | c[:, 3])


def _repeated(rgba: Sequence[int], n: int) -> pa.Array:
    return _rgba(np.tile(np.asarray(rgba, dtype=np.uint8), (n, 1)))


def _scalars(c: Column) -> list[Any]:
    n, width = len(c), c.style["width"]
    v = np.asarray(c.field("v"), dtype=np.float64).reshape(n * width)
    return [_col("scalars", "scalars", pa.array(v), np.arange(0, n * width + 1, width, dtype=np.int32))]


def _points(c: Column) -> list[Any]:
    """Rows of (k, 3) positions, with per-point colours (and labels)."""
    pos, lens = c.ragged("p", 3, np.float64)
    m = len(pos)
    offsets = np.zeros(len(lens) + 1, dtype=np.int32)
    np.cumsum(lens, out=offsets[1:])
    colours = _rgba(c.ragged("rgba", 4, np.uint8)[0]) if c.has("rgba") else _repeated(c.style["rgba"], m)
    cols = [_col("points", "positions", _vectors("points", "positions", pos, 3), offsets),
            _col("points", "radii", pa.array(np.full(m, c.style.get("radius", -2.0), dtype=np.float32)), offsets),
            _col("points", "colors", colours, offsets)]
    if c.has("label"):
        cols.append(_col("points", "labels", pa.array([lab for labs in c.field("label") for lab in labs],
                                                      type=pa.string()), offsets))
        cols.append(_col("points", "show_labels", pa.array(np.full(m, c.style.get("show_labels", True))), offsets))
    return cols


def _strips(c: Column) -> list[Any]:
    """One strip a row: a (k, 3) outline (an ellipse)."""
    strips = c.field("s")
    if isinstance(strips, np.ndarray):
        flat, lens = strips.reshape(-1, 3), np.full(len(strips), strips.shape[1], dtype=np.int64)
    else:
        parts = [np.asarray(s, dtype=np.float32).reshape(-1, 3) for s in strips]
        flat, lens = np.concatenate(parts), np.array([len(p) for p in parts], dtype=np.int64)
    n = len(lens)
    inner = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(lens, out=inner[1:])
    t = _proto("strips")["strips"][1]
    points = pa.FixedSizeListArray.from_arrays(
        pa.array(np.ascontiguousarray(flat, dtype=np.float32).reshape(-1)), type=t.value_type)
    rows = _unit(n)
    return [_col("strips", "strips", pa.ListArray.from_arrays(pa.array(inner), points, type=t), rows),
            _col("strips", "radii", pa.array(np.full(n, c.style.get("radius", -1.0), dtype=np.float32)), rows),
            _col("strips", "colors", _repeated(c.style["rgba"], n), rows)]


def _ellipsoids(c: Column) -> list[Any]:
    n = len(c)
    rows = _unit(n)
    vec = functools.partial(_vectors, "ellipsoids")
    return [_col("ellipsoids", "centers", vec("centers", np.asarray(c.field("c")), 3), rows),
            _col("ellipsoids", "half_sizes", vec("half_sizes", np.asarray(c.field("h")), 3), rows),
            _col("ellipsoids", "quaternions", vec("quaternions", np.asarray(c.field("q")), 4), rows),
            _col("ellipsoids", "colors", _repeated(c.style["rgba"], n), rows),
            _col("ellipsoids", "line_radii", pa.array(np.full(n, c.style.get("radius", -1.0), dtype=np.float32)),
                 rows)]


def _text(c: Column) -> list[Any]:
    rows = _unit(len(c))
    return [_col("text", "text", pa.array(c.field("text"), type=pa.string()), rows),
            _col("text", "level", pa.array(c.field("level"), type=pa.string()), rows)]


def field_arrow(values: Array | list[Any]) -> Any:
    """A record field as an arrow array: float vectors as lists of float64, the rest as given."""
    if isinstance(values, pa.Array):
        return values
    if isinstance(values, np.ndarray):
        return pa.array(values)
    first = values[0]
    if isinstance(first, np.ndarray):
        offsets = np.zeros(len(values) + 1, dtype=np.int32)
        np.cumsum([v.size for v in values], out=offsets[1:])
        flat = np.concatenate([v.ravel() for v in values]) if offsets[-1] else np.empty(0)
        return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, pa.float64()))
    if isinstance(first, str):  # labels, sensors, statuses: the type given, not inferred (~20 % less)
        return pa.array(values, type=pa.string())
    return pa.array(values)


def record_block(blocks: list[Array]) -> Any:
    """(rows, width) blocks as one list<float64> array: a vector per row, no per-row work."""
    flat = np.concatenate(blocks)
    n, width = flat.shape
    offsets = np.arange(0, n * width + 1, width, dtype=np.int32)
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat.ravel(), pa.float64()))


def _record(c: Column) -> list[Any]:
    """One AnyValues component per field, named by it, as rr.AnyValues.columns makes it: a field
    of lists (vectors, label lists) has a row per list, its items the row's batch; any other
    field one value a row."""
    rows = _unit(len(c))
    fields = {k: field_arrow(c.field(k)) for k in c.names()}
    fields.update({k: record_block(v) for k, v in c.blocks.items()})
    column = _list_column()
    return [column(_descriptor(k), a if pa.types.is_list(a.type) else pa.ListArray.from_arrays(rows, a))
            for k, a in fields.items()]


_KINDS = {"scalars": _scalars, "points": _points, "strips": _strips, "ellipsoids": _ellipsoids, "text": _text,
          "record": _record}


def components(c: Column) -> list[Any]:
    """The archetype columns of a pending Column (its kind says which archetype)."""
    build = _KINDS.get(c.kind)
    if build is None:
        raise AssertionError(f"unknown column kind {c.kind!r}")  # every kind is produced by the sink
    return build(c)
