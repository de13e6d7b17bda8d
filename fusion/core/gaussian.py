"""A Gaussian state estimate N(x, P) at an integer-nanosecond time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance, as_vector


@dataclass(frozen=True, slots=True)
class GaussianState:
    """Mean x (n,), covariance P (n, n), valid at time t_ns.

    Treat the arrays as read-only: every filter returns a new state and never writes into one.
    """

    x: Array
    P: Array
    t_ns: int

    @classmethod
    def create(cls, x: ArrayLike, P: ArrayLike, *, t_ns: int = 0) -> GaussianState:
        """Validated constructor: x finite, P symmetric positive definite of matching size."""
        xv = as_vector("x", x)
        return cls(xv, as_covariance("P", P, xv.shape[0]), int(t_ns))

    @property
    def ndim(self) -> int:
        return int(self.x.shape[0])

    @property
    def std(self) -> Array:
        """sqrt(diag(P)): the standard deviation of every component."""
        return np.sqrt(np.diagonal(self.P))


@dataclass(frozen=True, slots=True)
class Update:
    """What a measurement update produced.

    state: the posterior; y: the innovation z - h(x) (angles wrapped); S: its covariance;
    nis: y' S^-1 y; log_likelihood: log N(y; 0, S).
    """

    state: GaussianState
    y: Array
    S: Array
    nis: float
    log_likelihood: float
