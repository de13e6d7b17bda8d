"""The fine gate: predict and update every candidate (track, measurement) pair, keep those with
NIS <= chi2_m(probability), and score them for the assignment.

For a kept pair the assignment cost is the negative log-likelihood up to a constant,
    cost = NIS + ln det S      (= -2 log N(y; 0, S) - m ln 2 pi),
and its limit is g_m + ln det S: a pair alone is worth taking when cost < limit, i.e. when it
passes the gate. For an IMM, S and NIS are those of the mixture and ln det S is replaced by
-2 log L - m ln 2 pi - NIS with L the mixture likelihood.

This module holds what every gate shares (the stacked answers Part, the gathered Taken, the
kept pairs Gated and their collector Kept, the Gater interface) and the gate for any filter:
- PerPair: one filter predict per track and one update per pair (any filter: a UKF with
  custom state arithmetic, filters over models that take one state at a time, control inputs).
The batched gates and the choice between them live in fusion.tracking.batched_gating; the two
agree to 1e-12 where both apply (tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState, Update
from fusion.core.imm import Filter, IMMState
from fusion.core.measurement import MeasurementModel
from fusion.errors import NumericalError
from fusion.tracking.controls import InputTimeline
from fusion.tracking.results import Review
from fusion.tracking.trackset import TrackSet

LOG_2PI = math.log(2.0 * math.pi)



@dataclass(frozen=True)
class Part:
    """The filter's answers for k pairs of one measurement dimension, stacked: posterior X, P
    (and for an IMM the modes' MX, MP, MU), prior (prediction) x, P, innovation y, its
    covariance S, the measurement Jacobian H at the prior, and NIS."""

    X: Array
    P: Array
    prior_x: Array
    prior_P: Array
    y: Array
    S: Array
    H: Array
    nis: Array
    MX: Array | None = None
    MP: Array | None = None
    MU: Array | None = None


@dataclass(frozen=True)
class Taken:
    """Posteriors of the chosen pairs, in the order asked: stacked states, and the review arrays
    stacked per measurement dimension (their shapes differ with it): `review` holds, per part
    the pairs came from, (at: the positions of its pairs among those asked, prior_x, prior_P,
    y, S, H: their rows, in that order)."""

    X: Array
    P: Array
    MX: Array | None
    MP: Array | None
    MU: Array | None
    review: list[tuple[Array, Array, Array, Array, Array, Array]]

    def reviews(self, meas_pos: Array) -> tuple[list[Review], list[int]]:
        """Each pair's Review block and its row in it, with the pairs' measured positions
        `meas_pos` (k, p): one block per measurement dimension, shared by its pairs (with one
        dimension, X and P are the block: the pairs' estimates are views of their rows)."""
        if len(self.review) == 1:  # one dimension: every pair's row of one block, in order
            at, px, pP, y, S, H = self.review[0]
            return [Review(self.X, self.P, meas_pos, px, pP, y, S, H, self.MU)] * at.size, list(range(at.size))
        blocks: list[Review] = [None] * len(meas_pos)  # type: ignore[list-item]
        rows = [0] * len(meas_pos)
        for at, px, pP, y, S, H in self.review:
            rv = Review(self.X[at], self.P[at], meas_pos[at], px, pP, y, S, H, None if self.MU is None else self.MU[at])
            for r, a in enumerate(at.tolist()):
                blocks[a], rows[a] = rv, r
        return blocks, rows


@dataclass(frozen=True)
class Measured:
    """The measurements of one scan with their models and noise (R already resolved), and the
    same stacked once per measurement dimension: measurement j is row at[j] of Z[m], R[m]."""

    z: tuple[Array, ...]
    models: tuple[MeasurementModel, ...]
    R: tuple[Array, ...]
    Z: dict[int, Array]
    Rs: dict[int, Array]
    dims: np.ndarray  # (M,) each measurement's dimension
    at: np.ndarray  # (M,) its row in Z[dims[j]], Rs[dims[j]]

    @classmethod
    def of(cls, z: tuple[Array, ...], R: tuple[Array, ...], models: tuple[MeasurementModel, ...]) -> Measured:
        M = len(z)
        dims = np.fromiter((v.shape[0] for v in z), dtype=np.intp, count=M)
        if M and (dims == dims[0]).all():  # one dimension (a sensor's scan, usually): stacked as they come
            d = int(dims[0])
            return cls(z, models, R, {d: np.array(z, dtype=np.float64)}, {d: np.array(R, dtype=np.float64)}, dims,
                       np.arange(M, dtype=np.intp))
        at = np.zeros(M, dtype=np.intp)
        Zs: dict[int, Array] = {}
        Rs: dict[int, Array] = {}
        for m in np.unique(dims).tolist():
            rows = np.flatnonzero(dims == m)
            at[rows] = np.arange(rows.size)
            rl = rows.tolist()
            Zs[m] = np.array([z[j] for j in rl], dtype=np.float64)
            Rs[m] = np.array([R[j] for j in rl], dtype=np.float64)
        return cls(z, models, R, Zs, Rs, dims, at)


@dataclass(frozen=True)
class Gated:
    """Kept pairs, sorted by (measurement, track): indices, NIS, cost and limit per pair; pair
    p's answer is row where[p][1] of parts[where[p][0]]."""

    ti: np.ndarray
    mj: np.ndarray
    nis: np.ndarray
    cost: np.ndarray
    limit: np.ndarray
    parts: list[Part]
    where: np.ndarray  # (pairs, 2): part, row
    numerical_skips: int

    def take(self, pairs: list[int]) -> Taken:
        """The chosen pairs' answers, gathered from the stacks."""
        k = len(pairs)
        if len(self.parts) == 1:  # every pair from one part (one measurement dimension): its rows
            part, rows = self.parts[0], self.where[pairs, 1] if k else np.zeros(0, dtype=np.intp)
            MX, MP, MU = (None if a is None else a[rows] for a in (part.MX, part.MP, part.MU))
            review = [(np.arange(k, dtype=np.intp), part.prior_x[rows], part.prior_P[rows], part.y[rows], part.S[rows],
                       part.H[rows])]
            return Taken(part.X[rows], part.P[rows], MX, MP, MU, review)
        n = self.parts[0].X.shape[1] if self.parts else 0
        imm = bool(self.parts) and self.parts[0].MX is not None
        X, P = np.empty((k, n)), np.empty((k, n, n))
        MX = MP = MU = None
        if imm:
            M = self.parts[0].MX.shape[1]  # type: ignore[union-attr]
            MX, MP, MU = np.empty((k, M, n)), np.empty((k, M, n, n)), np.empty((k, M))
        where = self.where[pairs] if k else np.zeros((0, 2), dtype=np.intp)
        review = []
        for g in np.unique(where[:, 0]).tolist():
            at = np.flatnonzero(where[:, 0] == g)
            rows = where[at, 1]
            part = self.parts[g]
            X[at], P[at] = part.X[rows], part.P[rows]
            if imm:
                MX[at], MP[at], MU[at] = part.MX[rows], part.MP[rows], part.MU[rows]  # type: ignore[index]
            review.append((at, part.prior_x[rows], part.prior_P[rows], part.y[rows], part.S[rows], part.H[rows]))
        return Taken(X, P, MX, MP, MU, review)


class Gater(Protocol):
    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated: ...

    def predict(self, ts: TrackSet, t_ns: int, rows: np.ndarray) -> tuple[Array, Array, Array | None]:
        """Tracks `rows` (all at or before t_ns) predicted to t_ns: x, P (and IMM mode
        probabilities)."""
        ...


class Kept:
    """Collects kept pairs: (track, measurement, NIS, cost, limit) and where each answer lives,
    as one block of columns per part."""

    def __init__(self) -> None:
        self.blocks: list[tuple[np.ndarray, ...]] = []  # ti, mj, nis, cost, limit, part, row
        self.parts: list[Part] = []
        self.skips = 0

    def add_part(self, ti: np.ndarray, mj: np.ndarray, nis: Array, ll: Array, dim: int, g: float,
                 part: Part) -> None:
        """Pairs (ti[k], mj[k]) answered by row k of `part`; the ones inside the gate are kept."""
        cost = -2.0 * ll - dim * LOG_2PI
        self.parts.append(part)
        k = np.flatnonzero(nis <= g)
        c, v = cost[k], np.asarray(nis, dtype=np.float64)[k]
        self.blocks.append((ti[k], mj[k], v, c, c - v + g, np.full(k.size, len(self.parts) - 1), k))

    def add_gated(self, sub: Gated) -> None:
        base = len(self.parts)
        self.parts.extend(sub.parts)
        self.skips += sub.numerical_skips
        self.blocks.append((sub.ti, sub.mj, sub.nis, sub.cost, sub.limit, base + sub.where[:, 0], sub.where[:, 1]))

    def done(self) -> Gated:
        """The kept pairs sorted by (measurement, track)."""
        if not self.blocks:
            e, f = np.zeros(0, dtype=np.intp), np.zeros(0)
            return Gated(e, e, f, f, f, self.parts, np.zeros((0, 2), dtype=np.intp), self.skips)
        if len(self.blocks) == 1:  # one part (one measurement dimension): its columns as they are
            ti, mj, nis, cost, limit, part, row = self.blocks[0]
        else:
            ti, mj, nis, cost, limit, part, row = (np.concatenate(c) for c in zip(*self.blocks, strict=True))
        o = np.lexsort((ti, mj))
        return Gated(ti[o].astype(np.intp, copy=False), mj[o].astype(np.intp, copy=False),
                     nis[o].astype(np.float64, copy=False), cost[o].astype(np.float64, copy=False),
                     limit[o].astype(np.float64, copy=False), self.parts,
                     np.stack([part[o], row[o]], axis=1).astype(np.intp, copy=False), self.skips)


class PerPairGate:
    """One filter call per track (predict) and per pair (update); any filter."""

    def __init__(self, filt: Filter, thresholds: dict[int, float], inputs: InputTimeline | None = None) -> None:
        self.filter = filt
        self.g = thresholds
        self.inputs = inputs

    def _predict(self, state: GaussianState, t_ns: int) -> GaussianState:
        pred = self.filter.predict(state, t_ns)  # type: ignore[arg-type]
        d = None if self.inputs is None else self.inputs.offset(state.t_ns, t_ns)
        return pred if d is None else GaussianState(pred.x + d, pred.P, t_ns)

    def predict(self, ts: TrackSet, t_ns: int, rows: np.ndarray) -> tuple[Array, Array, Array | None]:
        preds = [self._predict(ts.state(i), t_ns) for i in rows.tolist()]  # type: ignore[arg-type]
        n = ts.layout.n_state
        X = np.stack([p.x for p in preds]) if preds else np.zeros((0, n))
        P = np.stack([p.P for p in preds]) if preds else np.zeros((0, n, n))
        mu = np.stack([p.mu for p in preds]) if preds and isinstance(preds[0], IMMState) else None
        return X, P, mu

    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated:
        preds: dict[int, GaussianState | IMMState] = {}
        kept = Kept()
        for i, j in zip(ci.tolist(), cj.tolist(), strict=True):
            pred = preds.get(i)
            if pred is None:
                pred = preds[i] = self._predict(ts.state(i), t_ns)  # type: ignore[arg-type]
            model = meas.models[j]
            try:
                up: Update = self.filter.update(pred, meas.z[j], model, R=meas.R[j])  # type: ignore[arg-type]
            except NumericalError:
                kept.skips += 1
                continue
            g = self.g[model.ndim_meas]
            if up.nis <= g:
                st = up.state
                imm = isinstance(st, IMMState)
                part = Part(st.x[None], st.P[None], pred.x[None], pred.P[None], up.y[None], up.S[None],
                            model.jacobian(pred.x)[None], np.array([up.nis]),
                            *((st.xs[None], st.Ps[None], st.mu[None]) if imm else ()))  # type: ignore[union-attr]
                kept.add_part(np.array([i]), np.array([j]), np.array([up.nis]), np.array([up.log_likelihood]),
                              model.ndim_meas, g, part)
        return kept.done()
