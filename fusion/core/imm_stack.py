r"""The IMM's predict and update on stacks: N (state, measurement) pairs in one call per mode.

The same equations as fusion.core.imm (mixing with Pi(dt) = expm(Lambda dt), each mode's EKF
predict and update, mode probabilities from the likelihoods, the moment-matched combination),
evaluated on stacks (each mode's predict and update with the filters' compiled kernels looped
over the stack, fusion.core.compiled_stack), for an IMM whose modes are extended Kalman filters
over motion models that broadcast. The update comes in two halves so that a gate computes the
posteriors of the pairs it keeps only: innovate_imm (everything up to NIS and the likelihood)
for every candidate pair, posterior_imm for the kept ones. For pair k with mode states
(x_kj, P_kj), probabilities mu_k and time step dt_k:
    c_k = mu_k Pi(dt_k),   w_kij = Pi(dt_k)_ij mu_ki / c_kj,
    x0_kj = sum_i w_kij x_ki,   P0_kj = sum_i w_kij (P_ki + (x_ki - x0_kj)(x_ki - x0_kj)')
    predict each mode;  update each mode with z_k:  y_kj, S_kj, L_kj
    mu'_kj = c_kj L_kj / sum_l c_kl L_kl,  y_k = sum_j c_kj y_kj,
    S_k = sum_j c_kj (S_kj + (y_kj - y_k)(y_kj - y_k)'),  NIS_k = y_k' S_k^-1 y_k.
A pair with dt_k = 0 is neither mixed nor predicted (as IMM.predict does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_imm import distinct, innovate_modes, mix_many, mixture_many, posterior_many, predict_many
from fusion.core.imm import IMM
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import MeasurementModel
from fusion.core.motion import LinearMotionModel
from fusion.errors import NumericalError


def stackable(imm: IMM) -> bool:
    """Every mode an EKF over a motion model that broadcasts over stacks."""
    return all(isinstance(f, ExtendedKalmanFilter) and f.motion.broadcasts for f in imm.filters)


@dataclass(frozen=True)
class StackPrediction:
    """Predicted mode states (N, M, ...), predicted mode probabilities c (N, M), and their
    combination (the prior shown for review)."""

    xs: Array
    Ps: Array
    c: Array
    x: Array
    P: Array


def _f64(a: Array) -> Array:
    return np.ascontiguousarray(a, dtype=np.float64)


def _stack_of(a: Array, shape: tuple[int, ...]) -> Array:
    """a broadcast to `shape`, float64 and C-contiguous (a itself where it has the shape)."""
    return _f64(a if a.shape == shape else np.broadcast_to(a, shape))


def predict_imm(imm: IMM, xs: Array, Ps: Array, mu: Array, dt: Array, steps: StepCache | None = None
                ) -> StackPrediction:
    """Mix and predict N IMM states by dt (N,) seconds each: the mixing and the modes' predicts
    and combination are compiled loops over the stack (fusion.core.compiled_imm); each mode's
    motion model gives its F, Q (and f if nonlinear) for the whole stack in one call, or once
    per distinct dt where dt alone sets them (kept in `steps` across calls if given)."""
    M, n = xs.shape[1], xs.shape[2]
    xs, Ps, mu = _f64(xs), _f64(Ps), _f64(mu)
    du, inv = distinct(_f64(dt))  # few distinct steps: Pi, and F, Q where dt alone sets them
    Pi = (np.stack([imm.transition(d) for d in du.tolist()]) if steps is None else steps.transitions(imm, du))[inv]
    c = np.einsum("km,kmj->kj", mu, Pi)
    moving = dt > 0
    sel = np.flatnonzero(moving)
    S, U = sel.size, du.size
    X0, P0 = mix_many(xs, Ps, mu, Pi, c, sel)
    F, Q, Xf = np.empty((M, max(S, U), n, n)), np.empty((M, max(S, U), n, n)), np.empty((M, S, n))
    Fi, Qi = np.empty((M, S), dtype=np.intp), np.empty((M, S), dtype=np.intp)
    use_f = np.zeros(M, dtype=np.bool_)
    if S:
        dts, per_row, per_dt = dt[sel], np.arange(S), inv[sel]
        by_dt = None if steps is None else steps.of(imm, du)
        for j, f in enumerate(imm.filters):
            m = f.motion
            if isinstance(m, LinearMotionModel):
                F[j, :U], Fi[j] = by_dt[j][0] if by_dt is not None else m.F(du), per_dt
            elif m.is_linear:
                F[j, :S], Fi[j] = m.jacobian(X0[j], dts), per_row
            else:  # f and its Jacobian at the mixed prior, together (terms shared: CoordinatedTurn)
                Xf[j], F[j, :S] = m.f_and_jacobian(X0[j], dts)
                Fi[j], use_f[j] = per_row, True
            if m.noise_depends_on_state:
                Q[j, :S], Qi[j] = m.Q(X0[j], dts), per_row
            else:
                Q[j, :U], Qi[j] = by_dt[j][1] if by_dt is not None else m.Q(np.zeros((U, n)), du), per_dt
    c = np.where(moving[:, None], c, mu)
    pxs, pPs, x, P = predict_many(xs, Ps, sel, X0, P0, F, Fi, Q, Qi, Xf, use_f, c)
    return StackPrediction(pxs, pPs, c, x, P)


class StepCache:
    """Each mode's F and Q for a stack of distinct steps du, where dt alone sets them (a linear
    motion model's F; Q of a model whose noise does not depend on the state), kept by the bytes
    of du: a sensor's scans repeat the same few steps, and the models' matrices of a step are a
    function of the step alone, so a kept one is the one the model would give (bit for bit).
    Also the stack of the mode transition matrices Pi(du) (IMM.transition of each step). Holds at
    most `size` stacks of each (forgets them all when full)."""

    def __init__(self, size: int = 256) -> None:
        self.size = size
        self._kept: dict[bytes, list[tuple[Array | None, Array | None]]] = {}
        self._pi: dict[bytes, Array] = {}

    def transitions(self, imm: IMM, du: Array) -> Array:
        key = du.tobytes()
        got = self._pi.get(key)
        if got is None:
            if len(self._pi) >= self.size:
                self._pi.clear()
            got = self._pi[key] = np.stack([imm.transition(d) for d in du.tolist()])
        return got

    def of(self, imm: IMM, du: Array) -> list[tuple[Array | None, Array | None]]:
        key = du.tobytes()
        got = self._kept.get(key)
        if got is None:
            if len(self._kept) >= self.size:
                self._kept.clear()
            n = imm.filters[0].motion.ndim_state
            got = self._kept[key] = [
                (np.array(f.motion.F(du)) if isinstance(f.motion, LinearMotionModel) else None,
                 None if f.motion.noise_depends_on_state else np.array(f.motion.Q(np.zeros((du.size, n)), du)))
                for f in imm.filters]
        return got


@dataclass(frozen=True)
class StackInnovation:
    """What a gate decides on, for N (predicted IMM state, measurement) pairs: each mode's
    innovation ys (N, M, m), its covariance Ss (N, M, m, m) and Jacobian Hs (N, M, m, n) at the
    mode's prior; the posterior mode probabilities mu (N, M); the mixture innovation y, its
    covariance S, NIS and log-likelihood; the measurement noise R (N, m, m); and each pair's
    row in the prediction (rows)."""

    ys: Array
    Ss: Array
    Hs: Array
    mu: Array
    y: Array
    S: Array
    nis: Array
    loglik: Array
    R: Array
    rows: np.ndarray


def innovate_imm(pred: StackPrediction, rows: np.ndarray, Z: Array, R: Array, model: MeasurementModel
                 ) -> StackInnovation:
    """The innovation half of the update of N pairs (predicted IMM state rows[k] of pred, one
    measurement Z[k], R[k] each: Z (N, m), R (N, m, m)): everything but the modes' posteriors.
    Raises NumericalError where some mode's S is not positive definite."""
    rows = np.ascontiguousarray(rows, dtype=np.intp)
    xs = pred.xs[rows]  # (N, M, n): the models broadcast over the mode axis too
    N, M, n = xs.shape
    m = Z.shape[1]
    ys = _f64(model.residual(Z[:, None, :], model.h(xs)))
    Hs = _stack_of(model.jacobian(xs), (N, M, m, n))
    R = _stack_of(R, (N, m, m))
    ok, Ss, ll = innovate_modes(_f64(pred.Ps), rows, ys, Hs, R)
    if not ok:
        raise NumericalError("an innovation covariance S is not positive definite")
    c = pred.c[rows]
    a = np.log(np.maximum(c, 1e-300)) + ll
    amax = a.max(axis=1, keepdims=True)
    mix_ll = amax[:, 0] + np.log(np.exp(a - amax).sum(axis=1))
    mu = np.exp(a - mix_ll[:, None])
    mu = mu / mu.sum(axis=1, keepdims=True)
    if M == 2:  # numpy's einsum sums longer mode axes in another order (the mixture is bit for bit its)
        y, S, nis = mixture_many(_f64(c), ys, Ss)
    else:
        y = np.einsum("km,kma->ka", c, ys)
        dy = ys - y[:, None, :]
        S = np.einsum("km,kmab->kab", c, Ss) + np.einsum("km,kma,kmb->kab", c, dy, dy)
        nis = np.einsum("ka,ka->k", y, np.linalg.solve(S, y[..., None])[..., 0])
    return StackInnovation(ys, Ss, Hs, mu, y, S, nis, mix_ll, R, rows)


def posterior_imm(pred: StackPrediction, inn: StackInnovation, keep: np.ndarray) -> tuple[Array, Array, Array, Array]:
    """The modes' posteriors of the innovated pairs `keep` (each mode's EKF update from its
    innovation) and their combination with the posterior mode probabilities: (xs, Ps, x, P)."""
    ok, xs, Ps, x, P = posterior_many(_f64(pred.xs), _f64(pred.Ps), inn.rows, inn.ys, inn.Hs, inn.R, _f64(inn.mu),
                                      keep.astype(np.intp))
    if not ok:
        raise NumericalError("an innovation covariance S is not positive definite")
    return xs, Ps, x, P
