"""The single-state filter calls as one call each that returns the result: C where it was built.

    predict(x, P, FQ, t_ns, check) -> GaussianState | int
    update(code, x, P, z, spec, R, t_ns) -> Update | int
    step(x, P, z, blob, t_ns) -> Update | int
    FilterCalls: ExtendedKalmanFilter's predict, update and step, the base that gives it them

predict is fusion.core.compiled_step.predict_fq (FQ = [F(dt); Q(dt)] of
fusion.core.transitions), returning GaussianState(x-, P-, t_ns), also where x- is not finite
when check is false; update is compiled_step.update_model (code = kind << 2 | CHECK_Z | CHECK_R,
the model's kernel_spec, R) returning the Update at t_ns; step is
fusion.core.compiled_packed.step_packed on the blob of fusion.core.step_plan. Every array
returned is fresh. A status other than OK is returned as compiled_step's int code (the caller
then takes its checked path, which raises the typed error), and NOT_TAKEN (-1) for arguments the
call does not take (the C calls read aligned native float64 arrays of any strides and an int
time; the numba twins refuse only a z that is not a float64 vector): the caller then hands them
to the `*_numba` twin or its general path.

predict, update and step are the C extension fusion.core._single (built by setup.py, optional:
an install without a C compiler goes on without it; then `COMPILED` is False and they are the
numba twins). The C calls run the numba kernels' arithmetic written out in the same order
without fused multiply-adds, so the results are the same bits (tests/core/test_single_c.py).
They exist for their cost, not their arithmetic: a numba call types each array argument (8 to 11
here) and its results are allocated around it, about 1.1 us of a ~1.8 us step; the C calls take
the arguments as they are and allocate and build the results themselves (~0.6 us a step).

FilterCalls (fusion/core/_filter_calls.c) is the base of ExtendedKalmanFilter (and so of
KalmanFilter) that gives it predict, update and step as C methods: the common case (no u, a
transition already cached; no R, a model with a compiled twin; for step, its plan's blob of the
time step already made) makes the call above from C, anything else goes to the filter's
`_predict_general` / `_update_general` / `_step_general` with the arguments as they came. What
it saves is the Python frames and attribute reads around the calls (~0.2-0.4 us each).
Without the extension it is FilterCallsPython, which goes to the general methods at once.
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_packed import step_packed
from fusion.core.compiled_step import NONFINITE, predict_fq, update_model, work_size
from fusion.core.gaussian import GaussianState, Update

NOT_TAKEN = -1
_F64 = np.dtype(np.float64)
_empty = np.empty
_ndarray = np.ndarray
_new = tuple.__new__  # GaussianState and Update are named tuples: built without their __new__
_ws: dict[tuple[int, int], Array] = {}  # scratch of the numba twins per (n, m); only read inside one call


def _scratch(n: int, m: int) -> Array:
    ws = _ws.get((n, m))
    if ws is None:
        ws = _ws[(n, m)] = np.empty(work_size(n, m))
    return ws


def predict_numba(x: Array, P: Array, FQ: Array, t_ns: int, check: bool) -> GaussianState | int:
    """`predict` through numba's predict_fq."""
    n = x.shape[0]
    xn, Pn = _empty(n), _empty((n, n))
    status = predict_fq(x, P, FQ, xn, Pn, _scratch(n, 0))
    if status == 0 or (status == NONFINITE and not check):
        return _new(GaussianState, (xn, Pn, t_ns))
    return int(status)


def update_numba(code: int, x: Array, P: Array, z: Array, spec: Array, R: Array, t_ns: int) -> Update | int:
    """`update` through numba's update_model (z a float64 vector, R a float64 matrix)."""
    if not (type(z) is _ndarray and z.dtype is _F64 and z.ndim == 1 and type(R) is _ndarray and R.dtype is _F64
            and R.ndim == 2):
        return NOT_TAKEN
    n, m = x.shape[0], z.shape[0]
    xn, Pn, y, S = _empty(n), _empty((n, n)), _empty(m), _empty((m, m))
    status, nis, ll = update_model(code, x, P, z, spec, R, xn, Pn, y, S, _scratch(n, m))
    if status != 0:
        return int(status)
    return _new(Update, (_new(GaussianState, (xn, Pn, t_ns)), y, S, nis, ll))


def step_numba(x: Array, P: Array, z: Array, blob: Array, t_ns: int) -> Update | int:
    """`step` through numba's step_packed (z a float64 vector)."""
    if not (type(z) is _ndarray and z.dtype is _F64 and z.ndim == 1):
        return NOT_TAKEN
    n, m = int(blob[1]), int(blob[2])
    xn, Pn, y, S = _empty(n), _empty((n, n)), _empty(m), _empty((m, m))
    status, nis, ll = step_packed(x, P, z, blob, xn, Pn, y, S)
    if status != 0:
        return int(status)
    return _new(Update, (_new(GaussianState, (xn, Pn, t_ns)), y, S, nis, ll))


class FilterCallsPython:
    """ExtendedKalmanFilter's predict, update and step where the C extension was not built: its
    general methods, which make the numba twins' calls (the C methods take their common case
    first)."""

    _transitions: object = None
    _plans: object = None
    _check = True
    _linear_only = False

    def predict(self, *args: object, **kwargs: object) -> GaussianState:
        """predict(state, t_ns, *, u=None): predict to t_ns (>= state.t_ns); u is the control
        input if the model takes one."""
        return self._predict_general(*args, **kwargs)  # type: ignore[attr-defined, no-any-return]

    def update(self, *args: object, **kwargs: object) -> Update:
        """update(state, z, model, *, R=None): fold z (taken at state.t_ns) in; R defaults to the
        model's."""
        return self._update_general(*args, **kwargs)  # type: ignore[attr-defined, no-any-return]

    def step(self, *args: object, **kwargs: object) -> Update:
        """step(state, t_ns, z, model, *, R=None, u=None): predict to t_ns, then fold z (taken at
        t_ns) in."""
        return self._step_general(*args, **kwargs)  # type: ignore[attr-defined, no-any-return]


try:
    from fusion.core._single import FilterCalls, predict, step, update
    from fusion.core._single import bind as _bind
except ImportError:  # built without a C compiler (setup.py: the extension is optional)
    COMPILED = False
    predict, update, step = predict_numba, update_numba, step_numba
    FilterCalls = FilterCallsPython  # type: ignore[misc, assignment]
else:
    COMPILED = True
    _bind(GaussianState, Update)
