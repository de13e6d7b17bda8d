"""Known control inputs: a timeline of held values, and what they add to a prediction.

A linear motion model with input, x(t1) = F(t1 - t0) x(t0) + contributions of the inputs, with
u piecewise constant (each input held from its time until the next; u = 0 before the first):
    Delta(t0, t1) = sum over the segments [a, b) of [t0, t1) of  F(t1 - b) B(b - a) u(a).
Known inputs move the mean only (P is unchanged), so a prediction without input plus Delta is
exact, whatever filter made it. The timeline holds every accepted input regardless of arrival
order; a prediction to t only reads inputs before t, so rerunning the scans after a late input
(the tracker rewinds to its time) gives exactly what in-order arrival gives.
"""

from __future__ import annotations

import bisect

import numpy as np

from fusion.core.checks import Array
from fusion.core.motion import LinearMotionModel
from fusion.core.timebase import dt_seconds


class InputTimeline:
    """Inputs of one source, by time (then seq): (t_ns, seq) -> u."""

    def __init__(self, motion: LinearMotionModel, dim: int) -> None:
        self.motion = motion
        self.dim = dim
        self._keys: list[tuple[int, int]] = []
        self._u: list[Array] = []

    def __len__(self) -> int:
        return len(self._keys)

    def add(self, t_ns: int, seq: int, u: Array) -> None:
        k = bisect.bisect_left(self._keys, (t_ns, seq))
        self._keys.insert(k, (t_ns, seq))
        self._u.insert(k, u)

    def items(self) -> list[tuple[int, int, Array]]:
        """(t_ns, seq, u) of every input held, in order."""
        return [(t, q, u) for (t, q), u in zip(self._keys, self._u, strict=True)]

    def at(self, t_ns: int) -> Array:
        """The input in force at t_ns (the last one at or before it; zero before any)."""
        k = bisect.bisect_right(self._keys, (t_ns, 2**63)) - 1
        return self._u[k] if k >= 0 else np.zeros(self.dim)

    def offset(self, t0_ns: int, t1_ns: int) -> Array | None:
        """Delta(t0, t1) (see the module docstring); None when no input acts on [t0, t1)."""
        lo = bisect.bisect_right(self._keys, (t0_ns, 2**63))
        hi = bisect.bisect_left(self._keys, (t1_ns, -1))
        edges = [t0_ns] + [self._keys[k][0] for k in range(lo, hi)] + [t1_ns]
        inputs = [self.at(t0_ns)] + [self._u[k] for k in range(lo, hi)]
        total: Array | None = None
        for a, b, u in zip(edges[:-1], edges[1:], inputs, strict=True):
            if b <= a or not u.any():
                continue
            B = self.motion.control(dt_seconds(a, b))
            part = self.motion.F(dt_seconds(b, t1_ns)) @ (B @ u)  # type: ignore[operator]
            total = part if total is None else total + part
        return total

    def forget_before(self, t_ns: int) -> list[tuple[int, int]]:
        """Drop the inputs superseded before t_ns (the one in force at t_ns is kept); their
        (t_ns, seq)."""
        k = bisect.bisect_right(self._keys, (t_ns, 2**63)) - 1
        if k <= 0:
            return []
        gone = self._keys[:k]
        del self._keys[:k]
        del self._u[:k]
        return gone
