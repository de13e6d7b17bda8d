"""The viewed tracks' rows between a record flush and the view flush that draws them
(fusion.io.track_rows: `Rows.score` makes them, `Rows.views` reads them): their stacked arrays
(`Stacked`) and what the views read of their estimates (`Fields`: prior, measured position,
innovation and its covariance, NIS, sensor, Jacobian, prior covariance, mode probabilities),
read in one pass over the estimates when they are scored, one list per field. What is kept is
bounded by the viewed tracks' rows, not by the number of tracks."""

from __future__ import annotations

from operator import attrgetter
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.tracking.results import Estimate

_FIELDS = ("prior_x", "meas_pos", "y", "S", "nis", "sensor_id", "H", "prior_P", "mode_probabilities")
_READ_FIELDS = attrgetter(*_FIELDS)


class Fields:
    """What the views read of the viewed rows' estimates, one list per field (_FIELDS), read in
    one pass at the record flush that scores them (an estimate is read while it is still in the
    cache, not again a view interval later, once per field)."""

    __slots__ = _FIELDS
    prior_x: list[Array | None]
    meas_pos: list[Array | None]
    y: list[Array | None]
    S: list[Array | None]
    nis: list[float | None]
    sensor_id: list[str]
    H: list[Array | None]
    prior_P: list[Array | None]
    mode_probabilities: list[Array | None]

    def __init__(self, cols: list[list[Any]]) -> None:
        for name, col in zip(_FIELDS, cols, strict=True):
            setattr(self, name, col)

    @classmethod
    def of(cls, estimates: list[Estimate]) -> Fields:
        cols = list(zip(*map(_READ_FIELDS, estimates), strict=True))
        return cls([list(col) for col in cols] if cols else [[] for _ in _FIELDS])

    def take(self, rows: list[int]) -> Fields:
        """The fields of some rows, in the order given."""
        return Fields([[col[i] for i in rows] for col in (getattr(self, n) for n in _FIELDS)])

    @classmethod
    def concat(cls, parts: list[Fields]) -> Fields:
        return cls([[x for p in parts for x in getattr(p, n)] for n in _FIELDS])


class Stacked:
    """The stacked arrays of the viewed tracks' rows of one record flush (or of several,
    concatenated), with what the views read of their estimates (f), their track ids and whether
    each is confirmed."""

    __slots__ = ("P", "TX", "W", "X", "arr", "conf", "err", "f", "ids", "matched", "nees", "std", "step", "t")

    def __init__(self, t: Array, step: Array, arr: Array, X: Array, P: Array, std: Array, err: Array,
                 matched: Array, nees: Array, TX: Array, W: Array, *, f: Fields, ids: list[int],
                 conf: Array) -> None:
        self.t, self.step, self.arr, self.X, self.P, self.std = t, step, arr, X, P, std
        self.err, self.matched, self.nees, self.TX, self.W = err, matched, nees, TX, W
        self.f, self.ids, self.conf = f, ids, conf

    @classmethod
    def concat(cls, parts: list[Stacked]) -> Stacked:
        arrays = [np.concatenate([getattr(p, f) for p in parts]) for f in
                  ("t", "step", "arr", "X", "P", "std", "err", "matched", "nees", "TX", "W")]
        return cls(*arrays, f=Fields.concat([p.f for p in parts]), ids=[i for p in parts for i in p.ids],
                   conf=np.concatenate([p.conf for p in parts]))
