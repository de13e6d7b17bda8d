"""F(dt) and Q(dt) of a linear motion model, stacked and kept per dt.

A LinearMotionModel's F and Q are functions of dt alone (its contract), so the pair computed
for a dt seen before is the pair computed again. `TransitionCache.get(dt_s)` returns
FQ = [F(dt); Q(dt)] as one read-only float64 array (2, n, n): one argument for the compiled
predict (fusion.core.compiled_step.predict_fq) instead of two model calls and a stack per
step. The cache holds at most `max_entries` steps and starts afresh when full (irregular
sensor timing gives many distinct dt; a regular one a handful). It is a dict (dt_s -> FQ) that
fills itself on a miss, so that a hit is one C-level lookup: `cache[dt_s]`.
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.core.motion import LinearMotionModel
from fusion.errors import ShapeError


class TransitionCache(dict[float, Array]):
    """FQ (2, n, n) per dt_s for one linear motion model: cache[dt_s]."""

    def __init__(self, motion: LinearMotionModel, *, max_entries: int = 256) -> None:
        super().__init__()
        self.motion = motion
        self._n = motion.ndim_state
        self._max = max_entries

    def __missing__(self, dt_s: float) -> Array:
        """[F(dt_s); Q(dt_s)], computed on the first request for this dt_s."""
        n = self._n
        F = np.asarray(self.motion.F(dt_s), dtype=np.float64)
        Q = np.asarray(self.motion.Q_dt(dt_s), dtype=np.float64)
        if F.shape != (n, n) or Q.shape != (n, n):
            raise ShapeError(
                f"{type(self.motion).__name__}: F(dt) and Q(dt) must be {n} x {n}, "
                f"got {F.shape} and {Q.shape} at dt = {dt_s} s")
        FQ = np.stack((F, Q))
        FQ.flags.writeable = False
        if len(self) >= self._max:
            self.clear()
        self[dt_s] = FQ
        return FQ
