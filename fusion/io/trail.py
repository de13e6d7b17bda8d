"""Which steps of a viewed track get a faint 2-sigma ellipse in the trajectory view's trail.

One ellipse per step would overlap into a "rope" (the ellipse is often wider than one step's
travel). So a step is drawn only when it is newer than the last drawn one and its ellipse cannot
overlap it: with r the 2-sigma radius of the largest axis (2 sqrt(lambda_max(P_pos))), a step at
p with radius r follows the last drawn (p0, r0) when

    |p - p0| >= SPACING (r0 + r)

(bounding circles, or spheres, apart by a gap). A stationary or slow track gets few ellipses, a
fast and certain one many; a track converging after birth shows its shrinking ellipses apart.
The choice is made in the order rows reach the sink, per track, in sensor time: rows older than
the last drawn one (revisions after late data) are not drawn again.
"""

from __future__ import annotations

import numpy as np

from fusion.core.checks import Array
from fusion.io.derive import eig_sym2
from fusion.io.view_kernels import trail_rows

SPACING = 1.25  # gap between neighbouring trail ellipses, as a multiple of the sum of their radii


def radii(P: Array) -> Array:
    """2-sigma radius of the largest axis of each position covariance (n, k, k) -> (n,): 2 sqrt of
    the largest eigenvalue (in closed form for k = 2: fusion.io.derive.eig_sym2)."""
    w = eig_sym2(P)[1] if P.shape[-1] == 2 else np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))[:, -1]
    return 2.0 * np.sqrt(np.clip(w, 0.0, None))


def pick(t_ns: Array, pos: Array, r: Array, last: tuple[int, Array, float] | None
         ) -> tuple[list[int], tuple[int, Array, float] | None]:
    """Rows (in the given order) to draw, and the new last drawn (t_ns, position, radius).
    t_ns (n,), pos (n, k), r (n,): one track's rows; `last`: what was drawn before (or None).
    Each choice depends on the one before: a compiled loop (fusion.io.view_kernels.trail_rows;
    a Python loop over floats cost ~0.5 us a row, numpy per row ~5)."""
    pos = np.ascontiguousarray(pos, dtype=np.float64)
    k = pos.shape[1]
    if last is None:
        has, lt, lp, lr = False, 0, np.zeros(k), 0.0
    else:
        has, lt, lp, lr = True, int(last[0]), np.asarray(last[1], dtype=np.float64), float(last[2])
    rows, t1, p1, r1 = trail_rows(np.ascontiguousarray(t_ns, dtype=np.int64), pos,
                                  np.ascontiguousarray(r, dtype=np.float64), has, lt, lp, lr, SPACING)
    if rows.size:  # (with nothing drawn before, the first row is: rows is empty only without rows)
        return rows.tolist(), (int(t1), p1, float(r1))
    return [], last
