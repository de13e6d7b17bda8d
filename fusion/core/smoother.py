r"""Fixed-interval Rauch-Tung-Striebel (RTS) smoother, and its fixed-lag variant.

Given a filter's posteriors x_k|k, P_k|k (k = 0 .. N), its predictions x_k+1|k, P_k+1|k and the
motion Jacobians F_k+1 = df/dx (x_k|k, dt_k+1) it used, the smoothed estimates given all data:
    C_k   = P_k|k F_k+1' P_k+1|k^-1          (the smoother gain)
    x_k|N = x_k|k + C_k (x_k+1|N - x_k+1|k)
    P_k|N = P_k|k + C_k (P_k+1|N - P_k+1|k) C_k'
backwards from x_N|N, P_N|N. C_k' is obtained by a Cholesky solve, P_k+1|k C_k' = F_k+1 P_k|k
(P_k+1|k is symmetric positive definite): no inverse is formed. For a linear Gaussian model the
result is the exact posterior given all N + 1 measurements (the batch least-squares solution);
for an EKF it is the extended RTS smoother, linearised where the filter linearised.

Arrays are indexed by filter step: x_pred[k], P_pred[k] and F[k] belong to the step from k - 1
to k (entry 0 is not used). `predictions` recomputes them from the filtered states and the
motion model exactly as the EKF computed them (F at the prior state x_k-1|k-1, Q(x_k-1|k-1, dt),
plus B u when given); a step of dt = 0 has F = I, Q = 0 and C = I.

Approximations, stated once:
- UKF tracks: smoothing with the EKF's linearisation of the UKF's filtered states (the UKF's own
  predictions are not the ones recomputed here).
- IMM tracks (`imm_predictions`): the combined estimate (x, P) is smoothed through the
  moment-matched mixture of the mode models, weighted by the mode probabilities w = mu_k after
  the step from k - 1 to k:
      x_k|k-1 = sum_j w_j f_j(x),   P_k|k-1 = sum_j w_j (F_j P F_j' + Q_j + d_j d_j'),
      d_j = f_j(x) - x_k|k-1,       cross-covariance P F', F = sum_j w_j F_j
  (x, P = x_k-1|k-1, P_k-1|k-1). The per-mode estimates and the mixing are not smoothed (no
  per-mode backward pass); using a single mode's model instead lets a low-noise mode that stays
  most probable through a manoeuvre pull the whole track onto one straight line.

The fixed-lag smoother with lag L gives x_k|min(k+L, N): for each k the same backward pass over
the window k .. k + L only. A service keeping the last L + 1 steps of a track gets x_k-L|k by
running `rts_smooth` on them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from fusion.core.checks import Array
from fusion.core.gaussian import GaussianState
from fusion.core.motion import MotionModel
from fusion.core.timebase import dt_seconds
from fusion.errors import ConfigError, NumericalError, ShapeError


class Estimate(Protocol):
    """What the smoother reads of a filtered state (GaussianState and IMMState both have it)."""

    x: Array
    P: Array
    t_ns: int


def _gain_T(P_filt: Array, P_pred: Array, F: Array, k: int) -> Array:
    """C_k' from P_k+1|k C_k' = F_k+1 P_k|k, by a Cholesky solve."""
    try:
        c = cho_factor(P_pred, lower=True, check_finite=False)
    except LinAlgError:
        raise NumericalError(f"predicted covariance P_{k + 1}|{k} is not positive definite") from None
    return cho_solve(c, F @ P_filt, check_finite=False)


def _backward(x_filt: Array, P_filt: Array, x_pred: Array, P_pred: Array, F: Array,
              lo: int, hi: int) -> tuple[Array, Array]:
    """RTS backward pass over steps lo .. hi (inclusive); returns x_k|hi, P_k|hi for those steps."""
    xs, Ps = x_filt[lo:hi + 1].copy(), P_filt[lo:hi + 1].copy()
    for k in range(hi - 1, lo - 1, -1):
        Ct = _gain_T(P_filt[k], P_pred[k + 1], F[k + 1], k)
        i = k - lo
        xs[i] = x_filt[k] + Ct.T @ (xs[i + 1] - x_pred[k + 1])
        Pk = P_filt[k] + Ct.T @ (Ps[i + 1] - P_pred[k + 1]) @ Ct
        Ps[i] = 0.5 * (Pk + Pk.T)
    return xs, Ps


def _check(x_filt: Array, P_filt: Array, x_pred: Array, P_pred: Array, F: Array) -> None:
    K, n = x_filt.shape
    for name, a, shape in (("P_filt", P_filt, (K, n, n)), ("x_pred", x_pred, (K, n)),
                           ("P_pred", P_pred, (K, n, n)), ("F", F, (K, n, n))):
        if a.shape != shape:
            raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")


def rts_smooth(x_filt: ArrayLike, P_filt: ArrayLike, x_pred: ArrayLike, P_pred: ArrayLike,
               F: ArrayLike) -> tuple[Array, Array]:
    """Smoothed x_k|N (K, n) and P_k|N (K, n, n) from the filtered sequence and its predictions."""
    a = [np.asarray(v, dtype=np.float64) for v in (x_filt, P_filt, x_pred, P_pred, F)]
    _check(*a)
    return _backward(*a, 0, a[0].shape[0] - 1)


def fixed_lag_smooth(x_filt: ArrayLike, P_filt: ArrayLike, x_pred: ArrayLike, P_pred: ArrayLike,
                     F: ArrayLike, *, lag: int) -> tuple[Array, Array]:
    """x_k|min(k+lag, N) and its covariance for every k: what a smoother lagging `lag` steps
    behind the filter outputs. lag = 0 is the filter; lag >= N is `rts_smooth`."""
    if lag < 0:
        raise ConfigError(f"lag must be >= 0 steps, got {lag}")
    a = [np.asarray(v, dtype=np.float64) for v in (x_filt, P_filt, x_pred, P_pred, F)]
    _check(*a)
    K = a[0].shape[0]
    xs, Ps = a[0].copy(), a[1].copy()
    for k in range(K):
        xw, Pw = _backward(*a, k, min(k + lag, K - 1))
        xs[k], Ps[k] = xw[0], Pw[0]
    return xs, Ps


def predictions(
    states: Sequence[Estimate],
    motion: MotionModel | Sequence[MotionModel],
    *,
    u: Sequence[ArrayLike | None] | None = None,
) -> tuple[Array, Array, Array]:
    """x_pred, P_pred, F of the EKF between consecutive filtered states (entry 0 is the first
    state itself, with F = I). `motion` is one model or one per state (the model of the step
    ending at that state); u[k] is the control input of the step ending at state k."""
    K = len(states)
    models = [motion] * K if isinstance(motion, MotionModel) else list(motion)
    if len(models) != K or (u is not None and len(u) != K):
        raise ShapeError(f"need one motion model (and input) per state: {K} states, {len(models)} models")
    n = states[0].x.shape[0]
    x_pred, P_pred, F = np.empty((K, n)), np.empty((K, n, n)), np.empty((K, n, n))
    x_pred[0], P_pred[0], F[0] = states[0].x, states[0].P, np.eye(n)
    for k in range(1, K):
        prev, m = states[k - 1], models[k]
        dt = dt_seconds(prev.t_ns, states[k].t_ns)
        Fk = np.asarray(m.jacobian(prev.x, dt), dtype=np.float64)
        x = np.asarray(m.f(prev.x, dt), dtype=np.float64)
        if u is not None and u[k] is not None:
            B = m.control(dt)
            if B is None:
                raise ConfigError(f"{type(m).__name__} takes no control input")
            x = x + B @ np.asarray(u[k], dtype=np.float64)
        P = Fk @ prev.P @ Fk.T + np.asarray(m.Q(prev.x, dt), dtype=np.float64)
        x_pred[k], P_pred[k], F[k] = x, 0.5 * (P + P.T), Fk
    return x_pred, P_pred, F


def smooth_track(
    states: Sequence[Estimate],
    motion: MotionModel | Sequence[MotionModel],
    *,
    u: Sequence[ArrayLike | None] | None = None,
) -> list[GaussianState]:
    """The fixed-interval RTS smoothing of one track's filtered states (see `predictions`)."""
    if not states:
        return []
    x_pred, P_pred, F = predictions(states, motion, u=u)
    x_filt = np.stack([s.x for s in states])
    P_filt = np.stack([s.P for s in states])
    xs, Ps = rts_smooth(x_filt, P_filt, x_pred, P_pred, F)
    return [GaussianState(xs[k], Ps[k], int(s.t_ns)) for k, s in enumerate(states)]


def imm_predictions(states: Sequence[Estimate], models: Sequence[MotionModel],
                    mu: ArrayLike) -> tuple[Array, Array, Array]:
    """`predictions` for an IMM track: the moment-matched mixture of the mode models with
    weights mu[k] (K, M), the mode probabilities after the step ending at state k."""
    K, M = len(states), len(models)
    w = np.asarray(mu, dtype=np.float64)
    if w.shape != (K, M):
        raise ShapeError(f"mu must have shape ({K}, {M}), got {w.shape}")
    n = states[0].x.shape[0]
    x_pred, P_pred, F = np.empty((K, n)), np.empty((K, n, n)), np.empty((K, n, n))
    x_pred[0], P_pred[0], F[0] = states[0].x, states[0].P, np.eye(n)
    for k in range(1, K):
        prev = states[k - 1]
        dt = dt_seconds(prev.t_ns, states[k].t_ns)
        fs = np.stack([np.asarray(m.f(prev.x, dt), dtype=np.float64) for m in models])
        Fs = np.stack([np.asarray(m.jacobian(prev.x, dt), dtype=np.float64) for m in models])
        Qs = np.stack([np.asarray(m.Q(prev.x, dt), dtype=np.float64) for m in models])
        x = w[k] @ fs
        d = fs - x
        P = np.einsum("j,jab->ab", w[k], Fs @ prev.P @ np.swapaxes(Fs, 1, 2) + Qs) + (d.T * w[k]) @ d
        x_pred[k], P_pred[k], F[k] = x, 0.5 * (P + P.T), np.einsum("j,jab->ab", w[k], Fs)
    return x_pred, P_pred, F


def smooth_imm_track(states: Sequence[Estimate], models: Sequence[MotionModel]) -> list[GaussianState]:
    """The RTS smoothing of an IMM track's combined estimates (states with x, P, t_ns and mu,
    e.g. IMMState), through the mixture of its modes' motion `models` (see `imm_predictions`)."""
    if not states:
        return []
    mu = np.stack([np.asarray(s.mu, dtype=np.float64) for s in states])  # type: ignore[attr-defined]
    x_pred, P_pred, F = imm_predictions(states, models, mu)
    xs, Ps = rts_smooth(np.stack([s.x for s in states]), np.stack([s.P for s in states]), x_pred, P_pred, F)
    return [GaussianState(xs[k], Ps[k], int(s.t_ns)) for k, s in enumerate(states)]
