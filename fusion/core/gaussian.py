"""A Gaussian state estimate N(x, P) at an integer-nanosecond time, and what an update produced.

Both are immutable records (named tuples): a filter step makes three of them, and a named
tuple is built in C, a few times cheaper than a frozen dataclass (whose constructor goes
through object.__setattr__ once per field). Fields are read by name (state.x, update.nis).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance, as_vector


class GaussianState(NamedTuple):
    """Mean x (n,), covariance P (n, n), valid at time t_ns.

    The constructor does not check; `create` does. Treat the arrays as read-only: every filter
    returns a new state and never writes into one.
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


class Update(NamedTuple):
    """What a measurement update produced.

    state: the posterior; y: the innovation z - h(x) (angles wrapped); S: its covariance;
    nis: y' S^-1 y; log_likelihood: log N(y; 0, S).
    """

    state: GaussianState
    y: Array
    S: Array
    nis: float
    log_likelihood: float
