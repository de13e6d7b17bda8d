"""The planned single-state step as one call that returns the Update: C where it was built.

    step(x, P, z, blob, t_ns) -> Update | int

x (n,), P (n, n), z (m,) and the blob of fusion.core.step_plan for (filter, model, dt), t_ns the
int time of the result. On OK the Update (GaussianState(x+, P+, t_ns), y, S, NIS,
log-likelihood), its four arrays fresh; otherwise the status of fusion.core.compiled_step (the
caller then takes its checked path, which raises the typed error), or NOT_TAKEN (-1) for
arguments the call does not take (z not a float64 vector; for the C call also an array that is
not aligned native float64), which the caller hands to `step_numba` or its general path.

`step` is the C extension fusion.core._packed_step (built by setup.py, optional: an install
without a C compiler goes on without it, and then `COMPILED` is False and `step` is
`step_numba`). Both run the arithmetic of fusion.core.compiled_packed.step_packed, the C one
written out in the same order without fused multiply-adds, so the results are the same bits
(tests/core/test_packed_c.py). The C call exists for its cost, not its arithmetic: a numba call
types each of its eight array arguments and the four results are allocated before it, about
1.1 us of a ~1.8 us step; the C call takes five arguments and allocates and builds the results
itself (~0.6 us).
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.core.compiled_packed import step_packed
from fusion.core.gaussian import GaussianState, Update

NOT_TAKEN = -1
_F64 = np.dtype(np.float64)
_empty = np.empty
_ndarray = np.ndarray
_new = tuple.__new__  # GaussianState and Update are named tuples: built without their __new__


def step_numba(x: Array, P: Array, z: Array, blob: Array, t_ns: int) -> Update | int:
    """`step` through numba's step_packed (any layout of x, P and z)."""
    if not (type(z) is _ndarray and z.dtype is _F64 and z.ndim == 1):
        return NOT_TAKEN
    n, m = int(blob[1]), int(blob[2])
    xn, Pn, y, S = _empty(n), _empty((n, n)), _empty(m), _empty((m, m))
    status, nis, ll = step_packed(x, P, z, blob, xn, Pn, y, S)
    if status != 0:
        return int(status)
    return _new(Update, (_new(GaussianState, (xn, Pn, t_ns)), y, S, nis, ll))


try:
    from fusion.core._packed_step import bind as _bind
    from fusion.core._packed_step import step
except ImportError:  # built without a C compiler (setup.py: the extension is optional)
    COMPILED = False
    step = step_numba
else:
    COMPILED = True
    _bind(GaussianState, Update)
