"""What a filter's fused step keeps per measurement model: its packed constants per time step.

A `StepPlan` belongs to one filter (its motion model's F, Q cache and its check flag) and one
measurement model with a compiled twin. `plan.blobs[dt_ns]` is the blob of
fusion.core.compiled_packed for that time step, [code, n, m, s | F | Q | spec | R | scratch];
`blob(plan, dt_ns)` builds it on the first request from the transition cache (F(dt), Q(dt) with
dt = dt_ns / 1e9, the pair predict uses), the model's kernel_spec and its R, and keeps it (at
most `max_entries` time steps; the plan starts afresh when full). Keyed by the integer time
step, a hit is one dict lookup, with no division and no float hashing.

The model's R and kernel_spec are validated and read-only from its construction on (R by
fusion.core.measurement.noise_covariance); the plan copies both once. `plan.R` is the model's R
array the plan was built from: a filter takes the plan only while `model.R is plan.R` (a model
given a new R gets a new plan). The blob's scratch is overwritten by every call and never read
outside one. A plan is a named tuple so that the step unpacks it in one operation.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_packed import HEAD, blob_size
from fusion.core.compiled_step import CHECK_Z
from fusion.core.measurement import MeasurementModel
from fusion.core.timebase import NS_PER_S
from fusion.core.transitions import TransitionCache


class StepPlan(NamedTuple):
    """The blobs per time step in ns for one filter and one model, and what the step needs."""

    blobs: dict[int, Array]
    R: Array  # the model's R when the plan was made (identity, not contents, is compared)
    n: int
    P_shape: tuple[int, int]
    m: int
    S_shape: tuple[int, int]
    head: Array  # the blob less F and Q: code, n, m, s | spec | R | scratch
    transitions: TransitionCache
    max_entries: int


def make_plan(transitions: TransitionCache, model: MeasurementModel, *, check: bool,
              max_entries: int = 256) -> StepPlan:
    """The (empty) plan of a filter with these transitions and check flag, for model."""
    spec = model.kernel_spec
    if spec is None or not model.kernel_kind:
        raise ValueError(f"{type(model).__name__} has no compiled twin")
    n, m, s = transitions.motion.ndim_state, model.ndim_meas, spec.shape[0]
    head = np.empty(blob_size(n, m, s) - 2 * n * n)
    head[:HEAD] = (model.kernel_kind << 2 | (CHECK_Z if check else 0), n, m, s)
    head[HEAD:HEAD + s] = spec
    head[HEAD + s:HEAD + s + m * m] = np.asarray(model.R, dtype=np.float64).ravel()
    return StepPlan({}, model.R, n, (n, n), m, (m, m), head, transitions, max_entries)


def blob(plan: StepPlan, dt_ns: int) -> Array:
    """plan.blobs[dt_ns], made and kept on the first request."""
    got = plan.blobs.get(dt_ns)
    if got is not None:
        return got
    FQ = plan.transitions[dt_ns / NS_PER_S]
    h, nn2 = plan.head, FQ.size
    out = np.empty(h.shape[0] + nn2)
    out[:HEAD] = h[:HEAD]
    out[HEAD:HEAD + nn2] = FQ.ravel()
    out[HEAD + nn2:] = h[HEAD:]
    if len(plan.blobs) >= plan.max_entries:
        plan.blobs.clear()
    plan.blobs[dt_ns] = out
    return out
