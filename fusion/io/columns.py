"""Pending rows of a recording, per entity, and their writing as Rerun columns.

A `Column` holds the rows of one entity until the sink flushes: three times per row (sensor time
`t`, tracker step `step`, arrival time `arrival`, integer ns) and the archetype's fields.
fusion.io.arrow_columns turns it into the arrow columns of one `send_columns` call. Rerun's cost
is mostly per call, whatever the number of rows (~50 us for an entity of scalars, ~190 for a
record's ~17 fields, here), so the sink keeps the number of entities per flush bounded and the
rows per call many.

Rows arrive in chunks: `add` buffers one row (Python values), `extend` appends a block of rows
whose fields are either sequences with one item per row or numpy arrays whose first axis is the
row (a (n, width) array of scalars, a (n, k, 3) array of n rows of k points), or `Ragged` points
(n rows of varying length as one flat array). Nothing is converted per row: at the flush each
field's chunks are concatenated once (numpy where every chunk is an array, a list otherwise).

Timelines: `t` and `arrival` are durations (seconds from the stream's start) when the times are
stream-relative and timestamps (dates) when they are epoch times (fusion.io.labels.is_epoch);
`step` is a sequence.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import chain
from typing import Any

import numpy as np
import pyarrow as pa

from fusion.core.checks import Array


class Ragged:
    """n rows of varying length as one block: `flat` (sum(lens), ...) and `lens` (n,)."""

    __slots__ = ("flat", "lens")

    def __init__(self, flat: Array, lens: Array) -> None:
        self.flat = flat
        self.lens = np.asarray(lens, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.lens)


class Column:
    """Rows of one entity: times, and per field its chunks (see the module docstring)."""

    __slots__ = ("_items", "blocks", "chunks", "kind", "n", "style")

    def __init__(self, kind: str, **style: Any) -> None:
        self.kind = kind
        self.style = style
        self.n = 0
        self.chunks: list[tuple[Any, Any, Any, dict[str, Any]]] = []  # (t, step, arrival, fields)
        self._items: list[tuple[int, int, int, dict[str, Any]]] = []  # rows of add(), not yet a chunk
        self.blocks: dict[str, list[Array]] = {}  # record fields as (rows, width) float blocks

    def __len__(self) -> int:
        return self.n

    def add(self, t_ns: int, step: int, arrival_ns: int, **fields: Any) -> None:
        self._items.append((t_ns, step, arrival_ns, fields))
        self.n += 1

    def _seal(self) -> None:
        """The buffered rows of `add` as one chunk (a list per field)."""
        if not self._items:
            return
        items, self._items = self._items, []
        fields = {k: [it[3][k] for it in items] for k in items[0][3]}
        self.chunks.append(([it[0] for it in items], [it[1] for it in items], [it[2] for it in items], fields))

    def extend(self, t_ns: Sequence[int] | Array, step: Sequence[int] | Array, arrival_ns: Sequence[int] | Array,
               blocks: dict[str, Array] | None = None, **fields: Any) -> None:
        """Many rows at once: times as arrays or lists, each field a sequence with one item per
        row or an array with one row per item of its first axis, and `blocks`: vector fields as
        (rows, width) arrays (a record's x, std, error)."""
        n = len(t_ns)
        if not n:
            return
        self._seal()
        for k, b in (blocks or {}).items():
            self.blocks.setdefault(k, []).append(np.asarray(b, dtype=np.float64))
        self.chunks.append((t_ns, step, arrival_ns, fields))
        self.n += n

    def times(self) -> tuple[Array, Array, Array]:
        """(t_ns, step, arrival_ns) of every row, int64 (new arrays)."""
        self._seal()
        t, step, arrival = (_int64([c[i] for c in self.chunks], self.n) for i in range(3))
        return t, step, arrival

    def first_times(self) -> tuple[int, int]:
        """(t_ns, arrival_ns) of the first row (the sink decides the kind of its time axes from them)."""
        self._seal()
        c = self.chunks[0]
        return int(c[0][0]), int(c[2][0])

    def field(self, name: str) -> Array | list[Any]:
        """Every row's value of a field: one arrow array when every chunk is one (lists of labels),
        one numpy array when every chunk is an array of the same trailing shape, else a list with
        one item per row."""
        self._seal()
        parts = [c[3][name] for c in self.chunks]
        if all(isinstance(p, pa.Array) for p in parts):  # built as arrow already (lists of labels)
            return pa.concat_arrays(parts) if len(parts) > 1 else parts[0]
        if all(isinstance(p, np.ndarray) for p in parts) and len({p.shape[1:] for p in parts}) == 1:
            return np.concatenate(parts) if len(parts) > 1 else parts[0]
        out: list[Any] = []
        for p in parts:
            out.extend(p.tolist() if isinstance(p, np.ndarray) and p.ndim == 1 else list(p))
        return out

    def names(self) -> list[str]:
        """The fields of its rows (every row has the same), in the order first given."""
        self._seal()
        return list(self.chunks[0][3]) if self.chunks else []

    def has(self, name: str) -> bool:
        self._seal()
        return bool(self.chunks) and name in self.chunks[0][3]

    def ragged(self, name: str, width: int, dtype: Any) -> tuple[Array, Array]:
        """A per-row block field (points, their colours) as (flat (sum(lens), width), lens)."""
        self._seal()
        flats, lens = [], []
        for c in self.chunks:
            p = c[3][name]
            if isinstance(p, Ragged):
                flats.append(np.asarray(p.flat, dtype=dtype).reshape(-1, width))
                lens.append(p.lens)
            elif isinstance(p, np.ndarray) and p.ndim == 3:  # (n, k, width): n rows of k
                flats.append(p.reshape(-1, width).astype(dtype, copy=False))
                lens.append(np.full(p.shape[0], p.shape[1], dtype=np.int64))
            else:  # one (k, width) block per row
                blocks = [np.asarray(b, dtype=dtype).reshape(-1, width) for b in p]
                flats.append(np.concatenate(blocks) if blocks else np.empty((0, width), dtype=dtype))
                lens.append(np.array([len(b) for b in blocks], dtype=np.int64))
        return np.concatenate(flats), np.concatenate(lens)


def stack(rows: Sequence[Array], shape: tuple[int, ...] | None = None) -> Array:
    """Equal-shaped arrays (n of them) as one float64 array (n, *shape), like np.stack (rows of
    different shapes raise ValueError). Float64 C-contiguous arrays (what the tracker's estimates
    hold) are joined as bytes into one buffer (~0.1 us per array here, against ~0.3-0.5 for
    np.concatenate and 0.6-1.8 for np.array over the list); anything else goes through np.stack.
    `shape` is the arrays' shape, needed when there may be none. Up to SMALL_STACK arrays go to
    np.array: the joined path's checks cost ~4 us whatever the count (10 states of 5: 7.3 us
    against 3.8 with np.array, 2026-12-08), which a batch of truth or a flush's few rows paid."""
    if not len(rows):
        return np.empty((0, *(shape or (0,))), dtype=np.float64)
    if len(rows) <= SMALL_STACK:
        return np.array(rows, dtype=np.float64)
    first = np.asarray(rows[0])
    if first.dtype == _F64:
        try:
            buf = bytearray().join(rows)  # type: ignore[arg-type]  # raises on lists, non-contiguous arrays
        except (TypeError, ValueError, BufferError):
            buf = None
        # every row float64 and of the first's shape: the bytes are the rows' values, in order
        if (buf is not None and len(buf) == len(rows) * first.nbytes and {r.dtype for r in rows} == {_F64}
                and {r.shape for r in rows} == {first.shape}):
            return np.frombuffer(buf, dtype=np.float64).reshape(len(rows), *first.shape)
    return np.stack(rows).astype(np.float64, copy=False)


def _int64(parts: list[Any], n: int) -> Array:
    """The n integers of `parts` (lists, arrays or other sequences) as one int64 array: lists in one
    pass over their items, arrays in one concatenation (200 chunks of 10 numbers: 65 us as lists,
    79 as arrays, against 215 and 104 through np.asarray per chunk; 2026-12-08, a slow hour)."""
    if all(type(p) is list for p in parts):
        return np.fromiter(chain.from_iterable(parts), dtype=np.int64, count=n)
    if all(isinstance(p, np.ndarray) for p in parts):  # each cast to int64 as it is copied in
        return np.concatenate(parts, dtype=np.int64, casting="unsafe")
    return np.concatenate([np.asarray(p, dtype=np.int64) for p in parts])


_F64 = np.dtype(np.float64)
SMALL_STACK = 32  # np.array is the faster below it (columns of 5 and of 5x5: 1, 3, 10, 30, 100, 1000 timed)
