"""The batched fine gates, and the choice of gate for a filter.

- Batched: an EKF over a motion model that broadcasts over stacks (`MotionModel.broadcasts`),
  an IMM of such EKFs (fusion.core.imm_stack), or a UKF with plain state arithmetic over such a
  model (fusion.core.ukf_stack): each candidate track predicted once, every pair of a scan
  updated at once per measurement dimension (the EKF's compiled kernels looped over the stack,
  fusion.core.compiled_stack; the UKF's equations as numpy operations on stacks), in two halves:
  the innovation (NIS, likelihood) of every candidate pair, then the posterior of the pairs
  inside the gate only (a radar's coarse gate passes ~5 candidates per kept pair);
- otherwise fusion.tracking.gating.PerPairGate, one filter call per track and per pair.
They agree to 1e-12 where both apply (tested); the gate's math is in fusion.tracking.gating.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_stack import innovate_stack, predict_stack, update_stack
from fusion.core.imm import IMM, Filter
from fusion.core.imm_stack import StackPrediction, StepCache, innovate_imm, posterior_imm, predict_imm, stackable
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import MeasurementModel
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.core.ukf_stack import innovate_ukf, posterior_ukf, predict_ukf, stackable_measurement
from fusion.core.ukf_stack import stackable as ukf_stackable
from fusion.errors import NumericalError
from fusion.tracking.controls import InputTimeline
from fusion.tracking.gating import Gated, Gater, Kept, Measured, Part, PerPairGate
from fusion.tracking.trackset import TrackSet


def make_gater(filt: Filter, thresholds: dict[int, float], inputs: InputTimeline | None = None) -> Gater:
    """The batched gate where the filter and its motion models allow it, else pair by pair.
    (A measurement model that takes one state at a time falls back to pairs within a scan.)
    Known control inputs add their offset to every prediction (fusion.tracking.controls)."""
    if isinstance(filt, ExtendedKalmanFilter) and filt.motion.broadcasts:
        return BatchedGate(filt, thresholds, inputs)
    if isinstance(filt, IMM) and stackable(filt) and inputs is None:
        return BatchedIMMGate(filt, thresholds)
    if isinstance(filt, UnscentedKalmanFilter) and ukf_stackable(filt) and inputs is None:
        return BatchedUKFGate(filt, thresholds)
    return PerPairGate(filt, thresholds, inputs)


class _Batched(ABC):
    """The shared driver of the batched gates: predict each candidate track once, group the
    candidate pairs by measurement dimension, run the stacked update per group, keep the pairs
    inside the gate."""

    def __init__(self, filt: Filter, thresholds: dict[int, float], inputs: InputTimeline | None = None) -> None:
        self.filter = filt
        self.g = thresholds
        self.inputs = inputs
        self._each = PerPairGate(filt, thresholds, inputs)

    @abstractmethod
    def _predict(self, ts: TrackSet, t_ns: int, tracks: np.ndarray) -> object:
        """The prediction of tracks (indices into ts) to t_ns, as stacks."""

    @abstractmethod
    def _innovate(self, pred: object, rows: np.ndarray, Z: Array, R: Array, model: MeasurementModel
                  ) -> tuple[Array, Array, object]:
        """(NIS, log-likelihood, what the posterior needs) for predicted rows `rows` and
        measurements Z: the half of the update a gate decides on."""

    @abstractmethod
    def _finish(self, inner: object, keep: np.ndarray) -> Part:
        """The stacked answers of the pairs `keep` (indices into the innovated pairs)."""

    def predict(self, ts: TrackSet, t_ns: int, rows: np.ndarray) -> tuple[Array, Array, Array | None]:
        if rows.size == 0:
            n = ts.layout.n_state
            return np.zeros((0, n)), np.zeros((0, n, n)), None
        pred = self._predict(ts, t_ns, rows)
        if isinstance(pred, StackPrediction):
            return pred.x, pred.P, pred.c
        return pred[0], pred[1], None  # type: ignore[index]

    def gate(self, ts: TrackSet, t_ns: int, ci: np.ndarray, cj: np.ndarray, meas: Measured) -> Gated:
        kept = Kept()
        if ci.size == 0:
            return kept.done()
        seen = np.zeros(len(ts), dtype=np.bool_)  # predict each candidate track once: tracks sorted,
        seen[ci] = True  # ci = tracks[row] (np.unique(ci, return_inverse=True) without its sort)
        tracks = np.flatnonzero(seen)
        row = (np.cumsum(seen) - 1)[ci]
        pred = self._predict(ts, t_ns, tracks)
        one = len(meas.Z) == 1  # one measurement dimension in the scan: every pair in one group
        dims = None if one else meas.dims[cj]
        for dim in sorted(meas.Z):
            sel = np.arange(cj.size) if dims is None else np.flatnonzero(dims == dim)
            if sel.size == 0:
                continue
            js = cj[sel]
            model = meas.models[int(js[0])]  # one model per dimension and sensor: pairs differ by z and R
            try:
                if not model.broadcasts:
                    raise NumericalError("not stackable")
                at = meas.at[js]
                nis, ll, inner = self._innovate(pred, row[sel], meas.Z[dim][at], meas.Rs[dim][at], model)
                keep = np.flatnonzero(nis <= self.g[dim])  # the posterior of kept pairs only
                part = self._finish(inner, keep)
            except NumericalError:  # a non-PD S somewhere in the group, or a model that takes one state
                kept.add_gated(self._each.gate(ts, t_ns, ci[sel], js, meas))
                continue
            kept.add_part(ci[sel][keep], js[keep], nis[keep], ll[keep], dim, self.g[dim], part)
        return kept.done()


class BatchedGate(_Batched):
    """Every candidate pair at once: the EKF equations of fusion.core.kalman on stacks."""

    filter: ExtendedKalmanFilter

    def _predict(self, ts: TrackSet, t_ns: int, tracks: np.ndarray) -> tuple[Array, Array]:
        m = self.filter.motion
        X, P = ts.X[tracks], ts.P[tracks]
        dt = (t_ns - ts.t_ns[tracks]) * 1e-9
        Xp, Pp = predict_stack(X, P, m.jacobian(X, dt), m.Q(X, dt))
        if not m.is_linear:
            Xp = m.f(X, dt)
        if self.inputs is not None:
            t0 = ts.t_ns[tracks]
            for t in np.unique(t0).tolist():
                d = self.inputs.offset(t, t_ns)
                if d is not None:
                    Xp[t0 == t] += d
        return Xp, Pp

    def _innovate(self, pred: object, rows: np.ndarray, Z: Array, R: Array, model: MeasurementModel
                  ) -> tuple[Array, Array, object]:
        Xp, Pp = pred[0][rows], pred[1][rows]  # type: ignore[index]
        Y = model.residual(Z, model.h(Xp))
        H = np.broadcast_to(model.jacobian(Xp), (rows.size, Z.shape[1], Xp.shape[1]))
        ok, S, nis, ll = innovate_stack(Pp, Y, H, R)
        if not ok.all():
            raise NumericalError("an innovation covariance S is not positive definite")
        return nis, ll, (Xp, Pp, Y, H, np.broadcast_to(R, S.shape), S)

    def _finish(self, inner: object, keep: np.ndarray) -> Part:
        Xp, Pp, Y, H, R, S = (a[keep] for a in inner)  # type: ignore[attr-defined]
        ok, Xn, Pn, _, nis, _ = update_stack(Xp, Pp, Y, H, R)
        if not ok.all():
            raise NumericalError("an innovation covariance S is not positive definite")
        return Part(Xn, Pn, Xp, Pp, Y, S, H, nis)


class BatchedIMMGate(_Batched):
    """Every candidate pair at once for an IMM of EKFs (fusion.core.imm_stack)."""

    filter: IMM

    def __init__(self, filt: Filter, thresholds: dict[int, float], inputs: InputTimeline | None = None) -> None:
        super().__init__(filt, thresholds, inputs)
        self._steps = StepCache()  # the modes' F and Q of the steps seen (a scan repeats a few)

    def _predict(self, ts: TrackSet, t_ns: int, tracks: np.ndarray) -> StackPrediction:
        return predict_imm(self.filter, ts.MX[tracks], ts.MP[tracks], ts.MU[tracks],  # type: ignore[index]
                           (t_ns - ts.t_ns[tracks]) * 1e-9, self._steps)

    def _innovate(self, pred: object, rows: np.ndarray, Z: Array, R: Array, model: MeasurementModel
                  ) -> tuple[Array, Array, object]:
        p: StackPrediction = pred  # type: ignore[assignment]
        inn = innovate_imm(p, rows, Z, R, model)
        return inn.nis, inn.loglik, (p, inn, model)

    def _finish(self, inner: object, keep: np.ndarray) -> Part:
        p, inn, model = inner  # type: ignore[misc]
        xs, Ps, x, P = posterior_imm(p, inn, keep)
        at = inn.rows[keep]
        px = p.x[at]
        H = model.jacobian(px)
        if H.shape != (keep.size, inn.y.shape[1], px.shape[1]):
            H = np.broadcast_to(H, (keep.size, inn.y.shape[1], px.shape[1]))
        return Part(x, P, px, p.P[at], inn.y[keep], inn.S[keep], H, inn.nis[keep], xs, Ps, inn.mu[keep])


class BatchedUKFGate(_Batched):
    """Every candidate pair at once for a UKF (fusion.core.ukf_stack); a measurement model whose
    mean or h does not stack goes pair by pair."""

    filter: UnscentedKalmanFilter

    def _predict(self, ts: TrackSet, t_ns: int, tracks: np.ndarray) -> tuple[Array, Array]:
        return predict_ukf(self.filter, ts.X[tracks], ts.P[tracks], (t_ns - ts.t_ns[tracks]) * 1e-9)

    def _innovate(self, pred: object, rows: np.ndarray, Z: Array, R: Array, model: MeasurementModel
                  ) -> tuple[Array, Array, object]:
        if not stackable_measurement(model):
            raise NumericalError("a measurement model whose mean does not stack")
        Xp, Pp = pred[0][rows], pred[1][rows]  # type: ignore[index]
        Y, S, nis, ll, rest = innovate_ukf(self.filter, Xp, Pp, Z, R, model)
        return nis, ll, (Xp, Pp, model, Y, S, nis, rest)

    def _finish(self, inner: object, keep: np.ndarray) -> Part:
        Xp, Pp, model, Y, S, nis, rest = inner  # type: ignore[misc]
        Xp, Pp, Y, S = Xp[keep], Pp[keep], Y[keep], S[keep]
        Xn, Pn = posterior_ukf(self.filter, Xp, Pp, Y, S, tuple(a[keep] for a in rest))
        H = np.broadcast_to(model.jacobian(Xp), (keep.size, Y.shape[1], Xp.shape[1]))
        return Part(Xn, Pn, Xp, Pp, Y, S, H, nis[keep])
