"""The viewed tracks' rows between a record flush and the view flush that draws them
(fusion.io.track_rows: `Rows.score` makes them, `Rows.views` reads them), as stacked arrays of
their own: the scored rows (times, x, P, sqrt(diag P), error, NEES, matched truth, world
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
from operator import is_not
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.io.columns import stack
from fusion.tracking.results import Estimate

# Updates' per-row blocks after `rows`, and Stacked's per-row arrays: positional, then keyword
_UPDATE_BLOCKS = ("Y", "S", "nis", "gain", "H", "Pm")
_POSITIONAL = ("t", "step", "arr", "X", "P", "std", "err", "matched", "nees", "TX", "W")
_KEYWORD = ("ids", "conf", "prior", "meas", "meas_pos", "mode")


class Updates:
    """One sensor's rows with an innovation: `rows` (indices into the Stacked), innovation `Y`
    (k, m), its covariance `S` (k, m, m), `nis` (k,), and where the gain is known (`gain` (k,)),
    the Jacobian `H` (k, m, d) and prior covariance `Pm` (k, d, d) (NaN elsewhere)."""

    __slots__ = ("H", "Pm", "S", "Y", "gain", "nis", "rows")

    def __init__(self, rows: Array, Y: Array, S: Array, nis: Array, gain: Array, H: Array, Pm: Array) -> None:
        self.rows, self.Y, self.S, self.nis, self.gain, self.H, self.Pm = rows, Y, S, nis, gain, H, Pm

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


class Stacked:
    """The viewed tracks' rows of one record flush (or of several, concatenated): see the module
    docstring. `ids` (n,) int64 track ids; `conf` (n,) whether each is confirmed."""

    __slots__ = ("P", "TX", "W", "X", "arr", "conf", "err", "ids", "matched", "meas", "meas_pos", "mode", "mu",
                 "nees", "prior", "std", "step", "t", "updates")

    def __init__(self, t: Array, step: Array, arr: Array, X: Array, P: Array, std: Array, err: Array,
                 matched: Array, nees: Array, TX: Array, W: Array, *, ids: Array, conf: Array, prior: Array,
                 meas: Array, meas_pos: Array, mode: Array, mu: Array | None, updates: dict[str, Updates]) -> None:
        self.t, self.step, self.arr, self.X, self.P, self.std = t, step, arr, X, P, std
        self.err, self.matched, self.nees, self.TX, self.W = err, matched, nees, TX, W
        self.ids, self.conf, self.prior, self.meas, self.meas_pos = ids, conf, prior, meas, meas_pos
        self.mode, self.mu, self.updates = mode, mu, updates

    @classmethod
    def of(cls, estimates: list[Estimate], t: Array, step: Array, arr: Array, X: Array, P: Array, std: Array,
           err: Array, matched: Array, nees: Array, TX: Array, W: Array, *, conf: Array, n_pos: int) -> Stacked:
        """The rows of `estimates` (the arrays' rows, in their order; every array a copy of its
        own), with the first `n_pos` components of their measured positions."""
        d = X.shape[1]
        # one list per field: a comprehension per field is faster than one pass unzipped
        E = estimates
        priors, mps, ys, Ss = [e.prior_x for e in E], [e.meas_pos for e in E], [e.y for e in E], [e.S for e in E]
        niss, sensors, Hs = [e.nis for e in E], [e.sensor_id for e in E], [e.H for e in E]
        Pms, mus = [e.prior_P for e in E], [e.mode_probabilities for e in E]
        has_prior = _present(priors)
        prior = X.copy()
        if has_prior.any():
            prior[has_prior] = stack([p for p in priors if p is not None])
        meas = _present(mps)
        try:  # every measured position of one length (one tracker's position space): stacked whole
            meas_pos = _filled(meas, mps, np.shape(mps[int(np.argmax(meas))]) if meas.any() else (n_pos,))[:, :n_pos]
        except ValueError:  # of different lengths: each cut to n_pos first
            meas_pos = _filled(meas, [p if p is None else p[:n_pos] for p in mps], (n_pos,))
        mode = _present(mus)
        mu = _filled(mode, mus, np.shape(mus[int(np.argmax(mode))])) if mode.any() else None
        innovated = _present(ys) & _present(Ss) & _present(niss)
        names = np.array(sensors, dtype=object)
        updates = {}
        for sensor in sorted(set(sensors)):
            ks = np.flatnonzero(innovated & (names == sensor))
            if not ks.size:
                continue
            pick = ks.tolist()
            Y = stack([ys[k] for k in pick])
            m = Y.shape[1]
            H_, Pm_ = [Hs[k] for k in pick], [Pms[k] for k in pick]
            gain = _present(H_) & _present(Pm_)
            updates[sensor] = Updates(ks, Y, stack([Ss[k] for k in pick]),
                                      np.array([niss[k] for k in pick], dtype=np.float64), gain,
                                      _filled(gain, H_, (m, d)), _filled(gain, Pm_, (d, d)))
        ids = np.array([e.track_id for e in E], dtype=np.int64)
        return cls(t, step, arr, X, P, std, err, matched, nees, TX, W, ids=ids, conf=conf, prior=prior, meas=meas,
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
