"""The viewed tracks' rows between a record flush and the view flush that draws them
(fusion.io.track_rows: `Rows.score` makes them, `Rows.views` reads them), as stacked arrays of
their own: the scored rows (times, x, the position block of P (Pp: what the views draw of
P, a sixth of it for a 5-component state), sqrt(diag P), error, NEES, matched truth, world
position) and what the views read of the estimates, stacked when the rows are scored, in one
pass over the estimates:

- `prior` (n, d): the prediction (x itself where there is none: a birth);
- `meas` (n,) and `meas_pos` (n, k): whether a measured position is known, and its first k
  components (NaN where none);
- `mode` (n,) and `mu` (n, modes): the IMM mode probabilities, where known (None if no row has any);
- `updates`: per sensor, its rows with an innovation (`Updates`).

Every array is a new one: a step's estimates are rows of its stacked arrays (x, P, y, S, H of
every track it updated), so keeping an estimate, or a view of its arrays, kept the whole step's
arrays alive until the view flush (the service's 100 MB saw-tooth). What is kept is bounded by
the viewed tracks' rows, not by the number of tracks."""

from __future__ import annotations

from collections.abc import Sequence
from itertools import compress, repeat
from operator import attrgetter, is_not
from typing import Any, NamedTuple

import numpy as np

from fusion.core.checks import Array
from fusion.io.columns import stack
from fusion.tracking.results import Estimate, Review

# Updates' per-row blocks after `rows`, and Stacked's per-row arrays: positional, then keyword
_UPDATE_BLOCKS = ("Y", "S", "nis", "gain", "K")
_POSITIONAL = ("t", "step", "arr", "X", "Pp", "std", "err", "matched", "nees", "TX", "W")
_KEYWORD = ("ids", "conf", "prior", "meas", "meas_pos", "mode")


class Updates:
    """One sensor's rows with an innovation: `rows` (indices into the Stacked), innovation `Y`
    (k, m), its covariance `S` (k, m, m), `nis` (k,), and where the gain is known (`gain` (k,)),
    the Kalman gain `K` (k, d, m) = P- H' S^-1 (NaN elsewhere): computed when the rows are
    stacked (`Stacked.of`, a record flush's few rows), so what waits for the view flush is K, not
    the Jacobian and the prior covariance it comes from."""

    __slots__ = ("K", "S", "Y", "gain", "nis", "rows")

    def __init__(self, rows: Array, Y: Array, S: Array, nis: Array, gain: Array, K: Array) -> None:
        self.rows, self.Y, self.S, self.nis, self.gain, self.K = rows, Y, S, nis, gain, K

    @classmethod
    def concat(cls, parts: list[tuple[int, Updates]]) -> Updates:
        """Parts with the row offset of their Stacked in the concatenation."""
        rows = np.concatenate([u.rows + off for off, u in parts])
        return cls(rows, *(np.concatenate([getattr(u, f) for _, u in parts]) for f in _UPDATE_BLOCKS))


def _present(values: Sequence[Any]) -> Array:
    """(n,) bool: which values are not None (a C-level pass: no Python frame per value)."""
    return np.fromiter(map(is_not, values, repeat(None)), dtype=bool, count=len(values))


def _filled(present: Array, values: Sequence[Array | None], shape: tuple[int, ...]) -> Array:
    """(n, *shape): the values stacked where `present`, NaN rows elsewhere."""
    if present.all():
        return stack(values, shape)
    out = np.full((len(values), *shape), np.nan)
    if present.any():
        out[present] = stack(list(compress(values, present.tolist())))
    return out


class EstimateColumns(NamedTuple):
    """What a flush reads of each estimate beside its arrays, as columns: track id (n,) int64,
    NIS (n,) float64 (NaN where there is none), whether it has one (n,) bool, sensor (n,) object,
    the seq and revision (n,) int64."""

    ids: Array
    nis: Array
    has_nis: Array
    sensor: Array
    seq: Array
    revision: Array

    @classmethod
    def of(cls, estimates: Sequence[Estimate]) -> EstimateColumns:
        n = len(estimates)
        niss = list(map(attrgetter("nis"), estimates))
        return cls(np.fromiter(map(attrgetter("track_id"), estimates), dtype=np.int64, count=n),
                   np.array(niss, dtype=np.float64), _present(niss),  # None (a birth's) as NaN
                   np.array(list(map(attrgetter("sensor_id"), estimates)), dtype=object),
                   np.fromiter(map(attrgetter("seq"), estimates), dtype=np.int64, count=n),
                   np.fromiter(map(attrgetter("revision"), estimates), dtype=np.int64, count=n))

    def take(self, rows: Array) -> EstimateColumns:
        return EstimateColumns(*(c[rows] for c in self))


class ReviewBlocks:
    """The distinct Review blocks of some estimates (fusion.tracking.results.Review: a scan's
    estimates share theirs) and each estimate's block and row in it."""

    __slots__ = ("_fields", "_flat", "blocks", "lens", "row", "which")

    def __init__(self, blocks: list[Review | None], which: Array, row: Array, lens: Array,
                 flat: dict[tuple[str, int | None], tuple[Array, Array]] | None = None,
                 fields: dict[str, tuple[list[Array | None], Array]] | None = None) -> None:
        self.blocks, self.which, self.row = blocks, which, row
        self.lens = lens  # (blocks,) int64: each block's rows (of each of its fields; 0 where there is no block)
        self._flat = {} if flat is None else flat  # (field, cut): the blocks concatenated, each block's offset
        self._fields = {} if fields is None else fields  # field: each block's array of it, and whether it has one

    @classmethod
    def of(cls, estimates: Sequence[Estimate]) -> ReviewBlocks:
        reviews = [e.review for e in estimates]
        n = len(reviews)
        keys = np.fromiter(map(id, reviews), dtype=np.int64, count=n)  # the same block, the same id
        _, first, which = np.unique(keys, return_index=True, return_inverse=True)
        blocks = [reviews[i] for i in first.tolist()]
        return cls(blocks, which, np.fromiter([e.row for e in estimates], dtype=np.int64, count=n),
                   np.array([0 if b is None else len(b.X) for b in blocks], dtype=np.int64))

    def subset(self, rows: Array) -> ReviewBlocks:
        """The same for the estimates `rows` (indices)."""
        return ReviewBlocks(self.blocks, self.which[rows], self.row[rows], self.lens, self._flat,
                            self._fields)  # the same blocks

    def _arrays(self, name: str) -> tuple[list[Array | None], Array]:
        """Each block's field `name` (None where there is no block, or it has not that field), and
        whether each block has it: read once per field, for this set of blocks and its subsets
        (a flush asks `has` and `take` of the same field several times)."""
        got = self._fields.get(name)
        if got is None:
            arrays = [None if b is None else getattr(b, name) for b in self.blocks]
            got = self._fields[name] = (arrays, np.array([a is not None for a in arrays], dtype=bool))
        return got

    def width(self, name: str) -> Array:
        """(n,) int64: the length of each estimate's row of the field (its block's second axis; 0
        where it has none): the innovation's dimension, of "y"."""
        w = np.array([0 if a is None else a.shape[1] for a in self._arrays(name)[0]], dtype=np.int64)
        return w[self.which]

    def rows_of(self, name: str, estimates: Sequence[Estimate], attr: str) -> Array:
        """The field's row of every estimate, stacked: from the blocks when every estimate has
        one (the tracker's), else each estimate's own attribute `attr` (x or P; the same values)."""
        has = self.has(name)
        if has.all():
            return self.take(name, np.arange(len(has)))
        return stack([getattr(e, attr) for e in estimates])

    def has(self, name: str) -> Array:
        """(n,) bool: whether each estimate's block has the field."""
        return self._arrays(name)[1][self.which]

    def take(self, name: str, at: Array, *, cut: int | None = None) -> Array:
        """The field's rows of the estimates `at` (each with the field), stacked (a new array):
        the blocks concatenated whole (their first `cut` columns; once per field, for this set of
        blocks and its subsets), then the rows picked."""
        got = self._flat.get((name, cut))
        if got is None:
            arrays, has = self._arrays(name)
            rows = self.lens * has  # a block's rows are its rows of every field it has
            off = np.cumsum(rows) - rows  # each block's first row in the concatenation
            parts = list(compress(arrays, has.tolist()))
            if cut is not None:  # blocks may differ in width (a sensor's measured positions): cut each
                parts = [a[:, :cut] for a in parts]
            got = self._flat[(name, cut)] = (np.concatenate(parts), off)
        flat, off = got
        return flat[off[self.which[at]] + self.row[at]]


class Stacked:
    """The viewed tracks' rows of one record flush (or of several, concatenated): see the module
    docstring. `ids` (n,) int64 track ids; `conf` (n,) whether each is confirmed."""

    __slots__ = ("Pp", "TX", "W", "X", "arr", "conf", "err", "ids", "matched", "meas", "meas_pos", "mode", "mu",
                 "nees", "prior", "std", "step", "t", "updates")

    def __init__(self, t: Array, step: Array, arr: Array, X: Array, Pp: Array, std: Array, err: Array,
                 matched: Array, nees: Array, TX: Array, W: Array, *, ids: Array, conf: Array, prior: Array,
                 meas: Array, meas_pos: Array, mode: Array, mu: Array | None, updates: dict[str, Updates]) -> None:
        self.t, self.step, self.arr, self.X, self.Pp, self.std = t, step, arr, X, Pp, std
        self.err, self.matched, self.nees, self.TX, self.W = err, matched, nees, TX, W
        self.ids, self.conf, self.prior, self.meas, self.meas_pos = ids, conf, prior, meas, meas_pos
        self.mode, self.mu, self.updates = mode, mu, updates

    @classmethod
    def of(cls, estimates: list[Estimate], t: Array, step: Array, arr: Array, X: Array, Pp: Array, std: Array,
           err: Array, matched: Array, nees: Array, TX: Array, W: Array, *, conf: Array, n_pos: int,
           blocks: ReviewBlocks | None = None, columns: EstimateColumns | None = None) -> Stacked:
        """The rows of `estimates` (the arrays' rows, in their order; every array a copy of its
        own; `Pp` their covariances' position blocks, (n, k, k)), with the first `n_pos`
        components of their measured positions. What the estimates' Review blocks hold is read
        block by block (`blocks`, theirs, or found here), not estimate by estimate, and their
        ids, NIS and sensors from `columns` (theirs, or read here)."""
        d = X.shape[1]
        E = estimates
        rv = ReviewBlocks.of(E) if blocks is None else blocks
        cols = EstimateColumns.of(E) if columns is None else columns
        prior = X.copy()
        has_prior = rv.has("prior_x")
        if has_prior.any():
            prior[has_prior] = rv.take("prior_x", np.flatnonzero(has_prior))
        meas = rv.has("meas_pos")
        if meas.any():
            at = np.flatnonzero(meas)
            got = rv.take("meas_pos", at, cut=n_pos)
            meas_pos = np.full((len(E), got.shape[1]), np.nan)
            meas_pos[at] = got
        else:
            meas_pos = np.full((len(E), n_pos), np.nan)
        mode = rv.has("MU")
        if mode.all():  # the tracker's: every estimate's mode probabilities a row of its block's MU
            mu = rv.take("MU", np.arange(len(E)))
        else:
            mus = list(map(attrgetter("mode_probabilities"), E))
            mode = _present(mus)
            mu = _filled(mode, mus, np.shape(mus[int(np.argmax(mode))])) if mode.any() else None
        innovated = rv.has("y") & rv.has("S") & cols.has_nis
        gains = rv.has("H") & rv.has("prior_P")
        updates = {}
        for sensor in sorted(set(cols.sensor.tolist())):
            ks = np.flatnonzero(innovated & (cols.sensor == sensor))
            if not ks.size:
                continue
            Y = rv.take("y", ks)
            m = Y.shape[1]
            S = rv.take("S", ks)
            gain = gains[ks]
            K = np.full((ks.size, d, m), np.nan)
            if gain.any():
                H, Pm = rv.take("H", ks[gain]), rv.take("prior_P", ks[gain])
                K[gain] = np.swapaxes(np.linalg.solve(S[gain], H @ Pm), 1, 2)  # P- H' S^-1, S symmetric
            updates[sensor] = Updates(ks, Y, S, cols.nis[ks], gain, K)
        return cls(t, step, arr, X, Pp, std, err, matched, nees, TX, W, ids=cols.ids, conf=conf, prior=prior, meas=meas,
                   meas_pos=meas_pos, mode=mode, mu=mu, updates=updates)

    @classmethod
    def concat(cls, parts: list[Stacked]) -> Stacked:
        arrays = [np.concatenate([getattr(p, f) for p in parts]) for f in _POSITIONAL]
        offsets = np.cumsum([0] + [len(p.t) for p in parts]).tolist()
        with_mu = [p.mu for p in parts if p.mu is not None]
        mu = None
        if with_mu:
            k = with_mu[0].shape[1]
            mu = np.concatenate([np.full((len(p.t), k), np.nan) if p.mu is None else p.mu for p in parts])
        updates = {s: Updates.concat([(off, p.updates[s]) for off, p in zip(offsets, parts, strict=False)
                                      if s in p.updates])
                   for s in sorted({s for p in parts for s in p.updates})}
        cat = {f: np.concatenate([getattr(p, f) for p in parts]) for f in _KEYWORD}
        return cls(*arrays, mu=mu, updates=updates, **cat)

    def take(self, rows: Array) -> Stacked:
        """The given rows (indices, increasing), in their order; each sensor's updates renumbered."""
        new = np.full(len(self.t), -1, dtype=np.int64)
        new[rows] = np.arange(len(rows))
        updates = {}
        for sensor, u in self.updates.items():
            keep = new[u.rows] >= 0
            if keep.any():
                updates[sensor] = Updates(new[u.rows[keep]], *(getattr(u, f)[keep] for f in _UPDATE_BLOCKS))
        return Stacked(*(getattr(self, f)[rows] for f in _POSITIONAL), mu=None if self.mu is None else self.mu[rows],
                       updates=updates, **{f: getattr(self, f)[rows] for f in _KEYWORD})
