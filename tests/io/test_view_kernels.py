"""The compiled view geometry (fusion.io.view_kernels) against the numpy and Python code it
replaced, kept here as the reference: the ellipse outlines bit for bit (float64 and the float32
a recording stores, 2-D and 3-D points), and the trail's choice row for row."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.io import trail
from fusion.io.derive import _CIRCLE, eig_sym2, ellipse_points


def _ellipse_reference(mean: np.ndarray, cov: np.ndarray, *, dims: int, dtype: type) -> np.ndarray:
    lo, hi, phi = eig_sym2(cov)
    a = 2.0 * np.sqrt(np.clip(lo, 0.0, None))[..., None]
    b = 2.0 * np.sqrt(np.clip(hi, 0.0, None))[..., None]
    cos, sin = np.cos(phi)[..., None], np.sin(phi)[..., None]
    out = np.zeros((*mean.shape[:-1], len(_CIRCLE), dims), dtype=dtype)
    tmp, x = np.empty(out.shape[:-1]), np.empty(out.shape[:-1])
    for k, (w0, w1, op) in enumerate(((a * sin, b * cos, np.subtract), (a * cos, b * sin, np.add))):
        np.multiply(w0, _CIRCLE[:, 0], out=tmp)
        op(mean[..., k, None], tmp, out=x)
        np.multiply(w1, _CIRCLE[:, 1], out=tmp)
        np.add(x, tmp, out=x)
        out[..., k] = x
    return out


def _pick_reference(t: np.ndarray, pos: np.ndarray, r: np.ndarray, last: tuple | None
                    ) -> tuple[list[int], tuple | None]:
    out: list[int] = []
    T, X, R = t.tolist(), pos.tolist(), r.tolist()
    lt, lp, lr = (None, None, 0.0) if last is None else (int(last[0]), list(last[1]), float(last[2]))
    for i, (ti, pi, ri) in enumerate(zip(T, X, R, strict=True)):
        if lt is None or (ti > lt and math.dist(pi, lp) >= trail.SPACING * (lr + ri)):
            out.append(i)
            lt, lp, lr = ti, pi, ri
    if lt is None:
        return out, None
    if out or last is None:
        return out, (lt, lp, lr)
    return out, last


@pytest.mark.parametrize(("dims", "dtype"), [(2, np.float64), (3, np.float32), (3, np.float64)])
def test_ellipse_points_are_the_numpy_evaluation_bit_for_bit(dims: int, dtype: type) -> None:
    rng = np.random.default_rng(7 + dims)
    n = 500
    A = rng.normal(size=(n, 2, 2)) * rng.uniform(0.01, 300.0, (n, 1, 1))
    cov = A @ np.swapaxes(A, 1, 2)
    cov[:20] = np.diag([4.0, 0.0])  # degenerate: one axis of zero length
    cov[20:40, 0, 1] -= 1e-9  # slightly asymmetric off-diagonal pairs
    mean = rng.normal(0.0, 5e3, (n, 2))
    got = ellipse_points(mean, cov, dims=dims, dtype=dtype)
    want = _ellipse_reference(mean, cov, dims=dims, dtype=dtype)
    assert got.dtype == want.dtype and got.shape == (n, 33, dims)
    np.testing.assert_array_equal(got, want)
    # leading axes other than one: the same points
    np.testing.assert_array_equal(ellipse_points(mean.reshape(5, 100, 2), cov.reshape(5, 100, 2, 2), dims=dims,
                                                 dtype=dtype), want.reshape(5, 100, 33, dims))


@pytest.mark.parametrize("seed", range(8))
def test_trail_pick_is_the_python_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    k = 2 if seed % 2 else 3
    last = None
    for _ in range(6):  # one track's rows over several flushes, what was drawn carried over
        n = int(rng.integers(0, 60))
        t = np.sort(rng.integers(0, 10_000, n)) if seed % 3 else rng.integers(0, 10_000, n)  # revisions: back in time
        pos = np.cumsum(rng.normal(0.0, 3.0, (n, k)), axis=0)
        r = rng.uniform(0.1, 4.0, n)
        got_rows, got_last = trail.pick(t, pos, r, last)
        want_rows, want_last = _pick_reference(t, pos, r, last)
        assert got_rows == want_rows
        if want_last is None:
            assert got_last is None
        else:
            assert got_last is not None
            assert (got_last[0], np.asarray(got_last[1]).tolist(), got_last[2]) == (
                want_last[0], np.asarray(want_last[1]).tolist(), want_last[2])
        last = got_last
