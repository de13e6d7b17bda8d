"""Pending rows of a recording, per entity, and their writing as Rerun columns.

A `Column` holds the rows of one entity until the sink flushes: three times per row (sensor time
`t`, tracker step `step`, arrival time `arrival`, integer ns) and the archetype's fields. `write`
turns it into one `send_columns` call. Rerun's cost is mostly per call (~150-300 us here, whatever
the number of rows), so the sink keeps the number of entities per flush bounded and the rows per
call many.

Timelines: `t` and `arrival` are durations (seconds from the stream's start) when the times are
stream-relative and timestamps (dates) when they are epoch times (fusion.io.labels.is_epoch);
`step` is a sequence.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np
import pyarrow as pa

from fusion.core.checks import Array


class Column:
    """Rows of one entity: times, and per field a list (one item per row, or a whole block)."""

    __slots__ = ("arrival_ns", "blocks", "data", "kind", "step", "style", "t_ns")

    def __init__(self, kind: str, **style: Any) -> None:
        self.kind = kind
        self.style = style
        self.t_ns: list[int] = []
        self.step: list[int] = []
        self.arrival_ns: list[int] = []
        self.data: dict[str, list[Any]] = defaultdict(list)
        self.blocks: dict[str, list[Array]] = defaultdict(list)  # record fields as (rows, width) blocks

    def __len__(self) -> int:
        return len(self.t_ns)

    def add(self, t_ns: int, step: int, arrival_ns: int, **fields: Any) -> None:
        self.t_ns.append(t_ns)
        self.step.append(step)
        self.arrival_ns.append(arrival_ns)
        for k, v in fields.items():
            self.data[k].append(v)

    def extend(self, t_ns: Array, step: Array, arrival_ns: Array, blocks: dict[str, Array] | None = None,
               **fields: Any) -> None:
        """Many rows at once: times as arrays, each field a sequence with one item per row, and
        `blocks`: vector fields as (rows, width) arrays (a record's x, std, error)."""
        for k, b in (blocks or {}).items():
            self.blocks[k].append(np.asarray(b, dtype=np.float64))
        self.t_ns.extend(np.asarray(t_ns).tolist())
        self.step.extend(np.asarray(step).tolist())
        self.arrival_ns.extend(np.asarray(arrival_ns).tolist())
        for k, v in fields.items():
            self.data[k].extend(v)


def time_column(rr: Any, name: str, t_ns: list[int], *, epoch: bool) -> Any:
    a = np.asarray(t_ns, dtype=np.int64)
    if epoch:
        return rr.TimeColumn(name, timestamp=a.astype("datetime64[ns]"))
    return rr.TimeColumn(name, duration=a.astype("timedelta64[ns]"))


def _matrix(rows: list[Array], width: int) -> Array:
    return np.asarray(rows, dtype=np.float64).reshape(len(rows), width)


def _points(rr: Any, c: Column) -> Any:
    """Points3D rows: each row a (k, 3) block of positions, with per-point colours (and labels)."""
    d = c.data
    lens = [len(p) for p in d["p"]]
    pos = np.concatenate(d["p"]) if lens else np.empty((0, 3))
    cols = np.concatenate(d["rgba"]) if "rgba" in d else np.tile(np.array(c.style["rgba"], np.uint8), (len(pos), 1))
    kw: dict[str, Any] = {"positions": pos, "colors": cols,
                          "radii": np.full(len(pos), c.style.get("radius", -2.0), dtype=np.float32)}
    if "label" in d:
        kw["labels"] = [lab for labs in d["label"] for lab in labs]
        kw["show_labels"] = np.full(len(pos), c.style.get("show_labels", True))
    return rr.Points3D.columns(**kw).partition(lens)


def _strips(rr: Any, c: Column) -> Any:
    """LineStrips3D rows: each row one strip (k, 3) (an ellipse outline)."""
    strips = c.data["s"]
    arr = [np.asarray(x, dtype=np.float32) for x in strips]
    n = len(strips)
    return rr.LineStrips3D.columns(strips=arr, colors=np.tile(np.array(c.style["rgba"], np.uint8), (n, 1)),
                                   radii=np.full(n, c.style.get("radius", -1.0), dtype=np.float32))


def _ellipsoids(rr: Any, c: Column) -> Any:
    d = c.data
    n = len(d["c"])
    return rr.Ellipsoids3D.columns(
        centers=np.asarray(d["c"]), half_sizes=np.asarray(d["h"]), quaternions=np.asarray(d["q"]),
        colors=np.tile(np.array(c.style["rgba"], np.uint8), (n, 1)),
        line_radii=np.full(n, c.style.get("radius", -1.0), dtype=np.float32),
    )


def components(rr: Any, c: Column) -> Any:
    """The archetype columns of a pending Column (its kind says which archetype)."""
    d = c.data
    n = len(c)
    if c.kind == "scalars":  # every row the same number of values: one series per value
        width = c.style["width"]
        return rr.Scalars.columns(scalars=_matrix(d["v"], width).ravel()).partition(np.full(n, width))
    if c.kind == "points":
        return _points(rr, c)
    if c.kind == "strips":
        return _strips(rr, c)
    if c.kind == "ellipsoids":
        return _ellipsoids(rr, c)
    if c.kind == "text":
        return rr.TextLog.columns(text=d["text"], level=d["level"])
    if c.kind == "record":  # structured rows: one AnyValues component per field
        fields = {k: _field(v) for k, v in d.items()}
        fields.update({k: _block(v) for k, v in c.blocks.items()})
        return rr.AnyValues.columns(**fields)
    raise AssertionError(f"unknown column kind {c.kind!r}")  # every kind is produced by the sink


def _field(values: list[Any]) -> Any:
    """A record field as an arrow array: float vectors as lists of float64, the rest as given."""
    first = values[0]
    if isinstance(first, np.ndarray):
        offsets = np.zeros(len(values) + 1, dtype=np.int32)
        np.cumsum([v.size for v in values], out=offsets[1:])
        flat = np.concatenate([v.ravel() for v in values]) if offsets[-1] else np.empty(0)
        return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, pa.float64()))
    return pa.array(values)


def _block(blocks: list[Array]) -> Any:
    """(rows, width) blocks as one list<float64> array: a vector per row, no per-row work."""
    flat = np.concatenate(blocks)
    n, width = flat.shape
    offsets = np.arange(0, n * width + 1, width, dtype=np.int32)
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat.ravel(), pa.float64()))
