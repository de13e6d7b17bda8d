"""The fine gate: predict and update every candidate (track, measurement) pair, keep those with
NIS <= chi2_m(probability), and score them for the assignment.

For a kept pair the assignment cost is the negative log-likelihood up to a constant,
    cost = NIS + ln det S      (= -2 log N(y; 0, S) - m ln 2 pi),
and its limit is g_m + ln det S: a pair alone is worth taking when cost < limit, i.e. when it
passes the gate. For an IMM, S and NIS are those of the mixture and ln det S is replaced by
-2 log L - m ln 2 pi - NIS with L the mixture likelihood.

Two implementations behind one interface, chosen once from a capability:
- Batched: an EKF over a motion model that broadcasts over stacks (`MotionModel.broadcasts`):
  every pair of a scan in one stacked predict + update per measurement dimension;
- PerPair: one filter predict per track and one update per pair (any filter: UKF, IMM, a
  model that takes one state at a time).
They agree to 1e-12 where both apply (tested).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState, Update
from fusion.core.imm import Filter, IMMState
from fusion.core.kalman import ExtendedKalmanFilter, predict_arrays, update_arrays
from fusion.core.measurement import MeasurementModel
from fusion.errors import NumericalError
from fusion.tracking.trackset import TrackSet

LOG_2PI = math.log(2.0 * math.pi)


@dataclass(frozen=True, slots=True)
class PairUpdate:
    """The filter's answer for one kept pair: posterior, prior and innovation."""

    state: GaussianState | IMMState
    prior_x: Array
    prior_P: Array
    y: Array
    S: Array
    H: Array
    nis: float


@dataclass(frozen=True)
class Measured:
    """The measurements of one scan with their models and noise (R already resolved)."""

    z: tuple[Array, ...]
    models: tuple[MeasurementModel, ...]
    R: tuple[Array, ...]


@dataclass(frozen=True)
class Gated:
    """Kept pairs, sorted by (measurement, track): indices, NIS, cost and limit per pair, and
    their updates (built on demand: only assigned pairs become objects)."""

    ti: np.ndarray
    mj: np.ndarray
    nis: np.ndarray
    cost: np.ndarray
    limit: np.ndarray
    updates: Sequence[PairUpdate] | _Lazy
    numerical_skips: int

    def update(self, p: int) -> PairUpdate:
        return self.updates[p]


class Gater(Protocol):
    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated: ...


def make_gater(filt: Filter, thresholds: dict[int, float]) -> Gater:
    """The batched gate where the filter and its motion model allow it, else pair by pair."""
    if isinstance(filt, ExtendedKalmanFilter) and filt.motion.broadcasts:
        return BatchedGate(filt, thresholds)
    return PerPairGate(filt, thresholds)


def _kept(rows: list[tuple[int, int, float, float, float]], updates: list, skips: int) -> Gated:
    order = sorted(range(len(rows)), key=lambda k: (rows[k][1], rows[k][0]))
    a = np.array([rows[k] for k in order], dtype=np.float64).reshape(len(rows), 5)
    return Gated(a[:, 0].astype(np.intp), a[:, 1].astype(np.intp), a[:, 2], a[:, 3], a[:, 4],
                 [updates[k] for k in order], skips)


class PerPairGate:
    """One filter call per track (predict) and per pair (update); any filter."""

    def __init__(self, filt: Filter, thresholds: dict[int, float]) -> None:
        self.filter = filt
        self.g = thresholds

    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated:
        preds: dict[int, GaussianState | IMMState] = {}
        rows: list[tuple[int, int, float, float, float]] = []
        ups: list[PairUpdate] = []
        skips = 0
        for i, j in zip(ci.tolist(), cj.tolist(), strict=True):
            pred = preds.get(i)
            if pred is None:
                pred = preds[i] = self.filter.predict(ts.tracks[i].state, t_ns)  # type: ignore[arg-type]
            model = meas.models[j]
            try:
                up: Update = self.filter.update(pred, meas.z[j], model, R=meas.R[j])  # type: ignore[arg-type]
            except NumericalError:
                skips += 1
                continue
            g = self.g[model.ndim_meas]
            if up.nis <= g:
                cost = -2.0 * up.log_likelihood - model.ndim_meas * LOG_2PI
                rows.append((i, j, up.nis, cost, cost - up.nis + g))
                ups.append(PairUpdate(up.state, pred.x, pred.P, up.y, up.S, model.jacobian(pred.x), up.nis))
        return _kept(rows, ups, skips)


class _Lazy:
    """Updates of the batched gate kept as stacks (group g, row k); `[p]` builds pair p's
    PairUpdate. Group -1 holds the few built pair by pair after a numerical fallback."""

    def __init__(self, t_ns: int, parts: list[tuple[np.ndarray, ...]], fallback: list[PairUpdate],
                 where: list[tuple[int, int]]) -> None:
        self.t_ns, self.parts, self.fallback, self.where = t_ns, parts, fallback, where

    def __getitem__(self, p: int) -> PairUpdate:
        g, k = self.where[p]
        if g < 0:
            return self.fallback[k]
        Xn, Pn, Xp, Pp, Y, S, H, nis = self.parts[g]
        # copies: a checkpointed state must not keep the whole stack alive
        return PairUpdate(GaussianState(Xn[k].copy(), Pn[k].copy(), self.t_ns), Xp[k], Pp[k], Y[k], S[k], H[k],
                          float(nis[k]))


class BatchedGate:
    """Every candidate pair at once: the EKF equations of fusion.core.kalman on stacks, grouped
    by measurement dimension. Same math as PerPairGate."""

    def __init__(self, filt: ExtendedKalmanFilter, thresholds: dict[int, float]) -> None:
        self.filter = filt
        self.motion = filt.motion
        self.g = thresholds
        self._each = PerPairGate(filt, thresholds)

    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated:
        if ci.size == 0:
            return _kept([], [], 0)
        m = self.motion
        X = np.stack([ts.tracks[i].state.x for i in ci.tolist()])
        P = np.stack([ts.tracks[i].state.P for i in ci.tolist()])
        dt = (t_ns - ts.t_ns[ci]) * 1e-9
        F = m.jacobian(X, dt)
        Xp, Pp = predict_arrays(X, P, F, m.Q(X, dt), None if m.is_linear else m.f(X, dt))
        dims = np.array([meas.models[j].ndim_meas for j in cj.tolist()])
        rows: list[tuple[int, int, float, float, float]] = []
        where: list[tuple[int, int]] = []
        parts: list[tuple[np.ndarray, ...]] = []
        fallback: list[PairUpdate] = []
        skips = 0
        for dim in np.unique(dims).tolist():
            sel = np.flatnonzero(dims == dim)
            js = cj[sel]
            model = meas.models[int(js[0])]  # one model per dimension and sensor: pairs differ by z and R
            Z = np.stack([meas.z[j] for j in js.tolist()])
            R = np.stack([meas.R[j] for j in js.tolist()])
            Xs, Ps = Xp[sel], Pp[sel]
            Y = model.residual(Z, model.h(Xs))
            H = np.broadcast_to(model.jacobian(Xs), (sel.size, dim, Xs.shape[1]))
            try:
                Xn, Pn, S, nis, ll = update_arrays(Xs, Ps, Y, H, R)
            except NumericalError:  # a non-PD S somewhere in the group: pair by pair, skipping it
                sub = self._each.gate(ts, t_ns, ci[sel], js, meas)
                skips += sub.numerical_skips
                for p in range(sub.ti.size):
                    rows.append((int(sub.ti[p]), int(sub.mj[p]), float(sub.nis[p]), float(sub.cost[p]),
                                 float(sub.limit[p])))
                    where.append((-1, len(fallback)))
                    fallback.append(sub.update(p))
                continue
            g = self.g[dim]
            cost = -2.0 * ll - dim * LOG_2PI
            ok = np.flatnonzero(nis <= g)
            parts.append((Xn, Pn, Xs, Ps, Y, S, H, nis))
            for k in ok.tolist():
                p = sel[k]
                rows.append((int(ci[p]), int(cj[p]), float(nis[k]), float(cost[k]), float(cost[k] - nis[k] + g)))
                where.append((len(parts) - 1, k))
        order = sorted(range(len(rows)), key=lambda k: (rows[k][1], rows[k][0]))
        a = np.array([rows[k] for k in order], dtype=np.float64).reshape(len(rows), 5)
        lazy = _Lazy(t_ns, parts, fallback, [where[k] for k in order])
        return Gated(a[:, 0].astype(np.intp), a[:, 1].astype(np.intp), a[:, 2], a[:, 3], a[:, 4], lazy, skips)
