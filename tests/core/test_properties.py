"""Property tests (hypothesis, bounded): the update never loses positive definiteness and never
increases uncertainty; wrap_angle maps into (-pi, pi] and is 2 pi periodic."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from fusion.core.kalman import update_single
from fusion.core.measurement import wrap_angle

PROFILE = settings(max_examples=150, deadline=None, derandomize=True)


@st.composite
def _problem(draw):
    """A random SPD P (n x n), SPD R (m x m), H (m x n) and innovation y from a drawn seed."""
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(1, 6))
    m = draw(st.integers(1, 4))
    p_scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    r_scale = draw(st.sampled_from([1e-4, 1.0, 1e4]))
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    P = p_scale * (A @ A.T + 1e-2 * np.eye(n))
    B = rng.standard_normal((m, m))
    R = r_scale * (B @ B.T + 1e-2 * np.eye(m))
    H = rng.standard_normal((m, n))
    y = rng.standard_normal(m)
    return seed, P, R, H, y


@PROFILE
@given(_problem())
def test_update_keeps_P_spd_and_shrinks_it(problem) -> None:
    seed, P, R, H, y = problem
    x = np.zeros(P.shape[0])
    _, Pn, _S, nis, ll = update_single(x, P, y, H, R)
    msg = f"seed={seed} n={P.shape[0]} m={R.shape[0]}"
    assert np.array_equal(Pn, Pn.T), msg
    scale = np.max(np.abs(P))
    w = np.linalg.eigvalsh(Pn)
    assert w[0] > 0.0, f"{msg}: smallest eigenvalue of P+ {w[0]:.3g}"
    # P- - P+ = K S K' is positive semi-definite (Loewner order P+ <= P-)
    d = np.linalg.eigvalsh(P - Pn)
    assert d[0] >= -1e-9 * scale, f"{msg}: P- - P+ has eigenvalue {d[0]:.3g} (scale {scale:.3g})"
    assert nis >= 0.0 and math.isfinite(ll), msg


ANGLES = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@PROFILE
@example(math.pi)
@example(-math.pi)
@example(math.nextafter(math.pi, 4.0))
@example(math.nextafter(-math.pi, -4.0))
@example(3 * math.pi)
@example(0.0)
@example(-0.0)
@given(ANGLES)
def test_wrap_angle_range(a: float) -> None:
    w = float(wrap_angle(a))
    assert -math.pi < w <= math.pi, f"wrap_angle({a!r}) = {w!r}"
    # same point on the circle
    assert abs(math.sin(w) - math.sin(a)) < 1e-9 and abs(math.cos(w) - math.cos(a)) < 1e-9


@PROFILE
@given(ANGLES, st.integers(-1000, 1000))
def test_wrap_angle_periodic(a: float, k: int) -> None:
    w1 = float(wrap_angle(a))
    w2 = float(wrap_angle(a + 2 * math.pi * k))
    # a + 2 pi k is rounded, so compare on the circle, to the rounding of |a + 2 pi k|
    tol = 8 * np.finfo(float).eps * (abs(a) + abs(2 * math.pi * k) + 1.0)
    d = abs(math.remainder(w1 - w2, 2 * math.pi))
    assert d <= tol, f"wrap_angle({a!r}) = {w1!r}, wrap_angle(+{k} turns) = {w2!r}"


def test_wrap_angle_vectorised_and_exact_on_the_principal_range() -> None:
    rng = np.random.default_rng(77)
    a = rng.uniform(-math.pi, math.pi, 1000)
    a = a[a > -math.pi]
    np.testing.assert_allclose(wrap_angle(a), a, rtol=0, atol=4.5e-16, err_msg="seed=77")
    assert float(wrap_angle(math.pi)) == math.pi
    assert float(wrap_angle(-math.pi)) == math.pi
