r"""The fused single-state step (fusion.core.compiled_step.step_model) with its constants packed.

A numba call costs about 80 ns per array argument (the dispatcher types each one) on top of a
fixed cost, as much as the 4x4 arithmetic of the step when there are a dozen of them. Here
everything that is fixed for one (filter, measurement model, dt) is packed into one float64
array, `blob`, built once (fusion.core.step_plan) and then passed as is. A step is then one
call with eight arrays (the state, z, the blob and the four fresh results) instead of eleven
and an integer:

    step_packed(x, P, z, blob, xn, Pn, y, S) -> (status, NIS, log-likelihood)

blob (row-major, flat) = [code, n, m, s | F(dt) (n x n) | Q(dt) (n x n) | spec (s) | R (m x m) | ws]
  code: kind << 2 | flags, as in step_model (the model's kernel_kind, CHECK_Z for a validating
  filter; never CHECK_R: R is the model's own, validated when the model was built);
  spec: the model's kernel_spec (s floats); ws: step_model's scratch, work_size(n, m) floats,
  overwritten by every call (the blob is only ever used inside one call, which holds the GIL).
xn (n,), Pn (n, n), y (m,), S (m, m): the results x+, P+, y, S, written by the call.

The call is step_model on views of blob: the same arithmetic in the same order, so the same
bits and the same statuses; SHAPE when x, P, z or the results do not have the sizes the blob
names (the caller then takes its checked path, which raises the typed error).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from fusion.core.compiled_step import SHAPE, step_model, work_size

HEAD = 4  # code, n, m, s


def blob_size(n: int, m: int, s: int) -> int:
    """Floats of a blob for an n-state, an m-measurement and a spec of s floats."""
    return HEAD + 2 * n * n + s + m * m + work_size(n, m)


@njit(cache=True, fastmath=False, error_model="numpy")
def step_packed(x: np.ndarray, P: np.ndarray, z: np.ndarray, blob: np.ndarray, xn: np.ndarray,
                Pn: np.ndarray, y: np.ndarray, S: np.ndarray) -> tuple[int, float, float]:
    code, n, m, s = int(blob[0]), int(blob[1]), int(blob[2]), int(blob[3])
    nn, mm = n * n, m * m
    o_f = HEAD
    o_s = o_f + 2 * nn
    o_r = o_s + s
    o_w = o_r + mm
    if (x.shape[0] != n or P.shape[0] != n or P.shape[1] != n or z.shape[0] != m
            or blob.shape[0] < o_w + work_size(n, m)):
        return SHAPE, 0.0, 0.0
    FQ = blob[o_f:o_s].reshape((2, n, n))
    R = blob[o_r:o_w].reshape((m, m))
    return step_model(code, x, P, FQ, z, blob[o_s:o_r], R, xn, Pn, y, S, blob[o_w:])
