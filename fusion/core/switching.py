r"""Mode switching in continuous time, for the IMM.

The mode is a continuous-time Markov chain with transition-rate matrix Lambda (M x M):
Lambda_ij >= 0 for i != j is the rate (1/s) of jumps from mode i to mode j, and
Lambda_ii = -sum_{j != i} Lambda_ij, so every row sums to 0 and the time spent in mode i is
exponential with mean tau_i = -1 / Lambda_ii (the mean sojourn time). Over dt seconds
    Pi(dt) = expm(Lambda dt),    Pi(dt)_ij = P(mode j at t + dt | mode i at t),
a row-stochastic matrix with Pi(0) = I and Pi(a + b) = Pi(a) Pi(b) (the chain is
time-homogeneous): two steps of 0.05 s switch exactly as one step of 0.1 s does, and a step of
dt = 0 does not switch at all. For small dt, Pi(dt) ~ I + Lambda dt.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import expm

from fusion.core.checks import Array, as_matrix, as_vector
from fusion.errors import ConfigError, TimeError


def rates_from_sojourn(sojourn_s: Sequence[float], jump: ArrayLike | None = None) -> Array:
    """The rate matrix Lambda of mean sojourn times tau_i (seconds) per mode.

    Lambda_ii = -1 / tau_i and Lambda_ij = J_ij / tau_i for i != j, where J_ij is the
    probability that a jump out of mode i lands in mode j: `jump` (zero diagonal, rows sum to
    1), or by default the exit rate split evenly, J_ij = 1 / (M - 1).
    """
    tau = as_vector("sojourn_s", sojourn_s)
    M = tau.shape[0]
    if M < 2:
        raise ConfigError("sojourn_s needs one mean sojourn time per mode, at least two modes")
    if (tau <= 0).any():
        raise ConfigError(f"mean sojourn times must be > 0 seconds, got {tau}")
    if jump is None:
        J = (np.ones((M, M)) - np.eye(M)) / (M - 1)
    else:
        J = as_matrix("jump", jump, M, M)
        if (J < 0).any() or np.diagonal(J).any() or not np.allclose(J.sum(axis=1), 1.0, atol=1e-9):
            raise ConfigError("jump must have a zero diagonal, entries >= 0 and rows summing to 1")
    return (J - np.eye(M)) / tau[:, None]


def check_rates(rates: ArrayLike, M: int | None = None) -> Array:
    """Lambda validated: square, finite, off-diagonals >= 0, rows summing to 0 (to 1e-9 of the
    largest rate); the diagonal is then set to minus the off-diagonal row sums exactly."""
    L = as_matrix("rates", rates, M, M)
    if L.shape[0] != L.shape[1]:
        raise ConfigError(f"rates must be square, got shape {L.shape}")
    off = L - np.diag(np.diagonal(L))
    if (off < 0).any():
        raise ConfigError("rates: off-diagonal transition rates must be >= 0")
    scale = max(float(np.abs(L).max()), 1e-300)
    if np.abs(L.sum(axis=1)).max() > 1e-9 * scale:
        raise ConfigError(f"rates: every row must sum to 0, got row sums {L.sum(axis=1)}")
    return off - np.diag(off.sum(axis=1))


def transition_matrix(rates: Array, dt_s: float) -> Array:
    """Pi(dt) = expm(Lambda dt).

    Two modes with exit rates a = Lambda_01, b = Lambda_10 have the closed form
        Pi_01 = a / (a + b) (1 - exp(-(a + b) dt)),   Pi_10 = b / (a + b) (1 - exp(-(a + b) dt))
    (1.6-2.2 us against 100-280 us for scipy's expm on a 2 x 2, measured here). Otherwise expm, clipped
    at 0 and renormalised per row (removing rounding of order 1e-16).
    """
    if not dt_s >= 0.0:
        raise TimeError(f"switching over a negative or NaN time step: dt_s = {dt_s}")
    M = rates.shape[0]
    if dt_s == 0.0:
        return np.eye(M)
    if M == 2:
        a, b = float(rates[0, 1]), float(rates[1, 0])
        if a + b == 0.0:
            return np.eye(2)
        g = -math.expm1(-(a + b) * dt_s) / (a + b)  # (1 - exp(-(a + b) dt)) / (a + b)
        return np.array([[1.0 - a * g, a * g], [b * g, 1.0 - b * g]])
    Pi = np.maximum(expm(rates * dt_s), 0.0)
    return Pi / Pi.sum(axis=1, keepdims=True)
