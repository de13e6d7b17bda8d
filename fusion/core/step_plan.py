"""What a filter's fused step keeps per measurement model: its packed constants per time step.

A `StepPlan` belongs to one filter (its motion model's F, Q cache and its check flag) and one
measurement model with a compiled twin. `plan[dt_ns]` is the blob of
fusion.core.compiled_packed for that time step, [code, n, m, s | F | Q | spec | R | scratch],
built on the first request from the transition cache (F(dt), Q(dt) with dt = dt_ns / 1e9, the
pair predict uses), the model's kernel_spec and its R, and kept (at most `max_entries` time
steps; the plan starts afresh when full). Keyed by the integer time step, a hit is one dict
lookup, with no division and no float hashing.

The model's R and kernel_spec are validated and read-only from its construction on (R by
noise_covariance); the plan copies both once. `plan.R` is the model's R array the plan was built
from: a filter takes the plan only while `model.R is plan.R` (a model given a new R gets a new
plan). The blob's scratch is overwritten by every call and never read outside one.
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_packed import HEAD, blob_size
from fusion.core.compiled_step import CHECK_Z
from fusion.core.measurement import MeasurementModel
from fusion.core.timebase import NS_PER_S
from fusion.core.transitions import TransitionCache


class StepPlan(dict[int, Array]):
    """blob (fusion.core.compiled_packed) per time step in ns, for one filter and one model."""

    def __init__(self, transitions: TransitionCache, model: MeasurementModel, *, check: bool,
                 max_entries: int = 256) -> None:
        super().__init__()
        spec = model.kernel_spec
        if spec is None or not model.kernel_kind:
            raise ValueError(f"{type(model).__name__} has no compiled twin")
        self.model = model
        self.R = model.R
        n, m = transitions.motion.ndim_state, model.ndim_meas
        self._transitions = transitions
        self._max = max_entries
        self.n, self.m = n, m
        self.P_shape, self.S_shape = (n, n), (m, m)
        s = spec.shape[0]
        head = np.empty(blob_size(n, m, s) - 2 * n * n)  # all but F and Q, which are per time step
        head[:HEAD] = (model.kernel_kind << 2 | (CHECK_Z if check else 0), n, m, s)
        head[HEAD:HEAD + s] = spec
        head[HEAD + s:HEAD + s + m * m] = np.asarray(self.R, dtype=np.float64).ravel()
        self._head = head

    def __missing__(self, dt_ns: int) -> Array:
        """The blob for a time step not seen (or forgotten) before."""
        FQ = self._transitions[dt_ns / NS_PER_S]
        h, nn2 = self._head, FQ.size
        blob = np.empty(h.shape[0] + nn2)
        blob[:HEAD] = h[:HEAD]
        blob[HEAD:HEAD + nn2] = FQ.ravel()
        blob[HEAD + nn2:] = h[HEAD:]
        if len(self) >= self._max:
            self.clear()
        self[dt_ns] = blob
        return blob
