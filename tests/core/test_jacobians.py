"""Analytic Jacobians against central finite differences.

Central differences with step h_j = 1e-6 * max(1, |x_j|) have truncation error O(h^2) and
rounding error O(eps |f| / h); the tolerance 1e-6 (relative to max(1, |J|)) sits well above
both for the states used here.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.measurement import Radar2D, Radar3D, wrap_angle
from fusion.core.motion import CoordinatedTurn
from fusion.models.helix import HelixDoc, HelixExact


def _fd(fun, x: np.ndarray, rel: float = 1e-6) -> np.ndarray:
    cols = []
    for j in range(x.size):
        h = rel * max(1.0, abs(x[j]))
        e = np.zeros_like(x)
        e[j] = h
        cols.append((fun(x + e) - fun(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


def _assert_jac(J: np.ndarray, Jfd: np.ndarray, tol: float, msg: str) -> None:
    err = np.abs(J - Jfd) / np.maximum(1.0, np.abs(Jfd))
    i = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() < tol, f"{msg}: entry {i} analytic {J[i]!r} vs finite difference {Jfd[i]!r}"


# --- coordinated turn -------------------------------------------------------------------------

CT = CoordinatedTurn(q_accel=1.0, q_turn=0.1)
OMEGAS = {
    "omega0": 0.0,
    "omega1e-9": 1e-9,
    "omega-5e-7": -5e-7,  # |omega dt| below the series threshold 1e-6
    "omega2e-6": 2e-6,  # just above it: the closed form
    "omega1e-4": 1e-4,
    "omega0.05": 0.05,
    "omega-0.3": -0.3,
    "omega2": 2.0,
}
DTS = (0.1, 1.0)


@pytest.mark.parametrize("dt", DTS, ids=[f"dt{d}" for d in DTS])
@pytest.mark.parametrize("omega", list(OMEGAS), ids=list(OMEGAS))
def test_coordinated_turn_jacobian(omega: str, dt: float) -> None:
    x = np.array([120.0, 14.0, -40.0, -9.0, OMEGAS[omega]])
    J = CT.jacobian(x, dt)
    # the omega column's finite difference needs a step larger than the series threshold
    Jfd = _fd(lambda s: CT.f(s, dt), x)
    h = 1e-4
    e4 = np.array([0.0, 0.0, 0.0, 0.0, h])
    Jfd[:, 4] = (CT.f(x + e4, dt) - CT.f(x - e4, dt)) / (2 * h)
    # O(h^2) truncation of the omega column: third derivative of f in omega ~ |v| dt^4
    _assert_jac(J, Jfd, 1e-6, f"CT omega={OMEGAS[omega]} dt={dt}")


def _ct_reference_jacobian(x: np.ndarray, dt: float) -> np.ndarray:
    """The CT Jacobian from numerically stable closed forms (1 - cos = 2 sin^2(wt/2)) and
    the Taylor series for the omega derivatives: accurate to ~1e-15 for |omega dt| < 1e-2."""
    _, vx, _, vy, w = x
    wt = w * dt
    s, c = np.sin(wt), np.cos(wt)
    sw = dt * (1 - wt**2 / 6 + wt**4 / 120 - wt**6 / 5040)
    cw = dt * (wt / 2 - wt**3 / 24 + wt**5 / 720)
    dsw = dt**2 * (-wt / 3 + wt**3 / 30 - wt**5 / 840)
    dcw = dt**2 * (0.5 - wt**2 / 8 + wt**4 / 144)
    J = np.eye(5)
    J[0, 1], J[0, 3], J[0, 4] = sw, -cw, dsw * vx - dcw * vy
    J[1, 1], J[1, 3], J[1, 4] = c, -s, -dt * (s * vx + c * vy)
    J[2, 1], J[2, 3], J[2, 4] = cw, sw, dcw * vx + dsw * vy
    J[3, 1], J[3, 3], J[3, 4] = s, c, dt * (c * vx - s * vy)
    return J


SMALL = (0.0, 3e-7, 9.9e-7, 1.01e-6, 2e-6, 1e-5, 1e-4, 1e-3)


@pytest.mark.parametrize("wt", SMALL, ids=[f"wt{w:g}" for w in SMALL])
def test_coordinated_turn_small_omega_accurate(wt: float) -> None:
    """Near omega dt = 0 (both sides of the series threshold 1e-6) J is accurate to 1e-9 and f
    to 1e-13. (1 - cos(wt)) / w computed as written loses about half the digits just above the
    threshold (J[0, 4] off by 2.2e-5 relative at omega dt = 2e-6 before the fix); the remaining
    error comes from d(s/w)/dw = (dt c - s/w)/w, about eps dt / w (2.6e-10 here)."""
    dt = 1.0
    x = np.array([120.0, 14.0, -40.0, -9.0, wt / dt])
    Jref = _ct_reference_jacobian(x, dt)
    _assert_jac(CT.jacobian(x, dt), Jref, 1e-9, f"CT omega dt={wt}")
    fref = Jref[:4, :4] @ x[:4]
    fref = np.append(fref, x[4])  # f is linear in (px, vx, py, vy) for fixed omega
    np.testing.assert_allclose(CT.f(x, dt), fref, rtol=1e-13, atol=1e-12)


def test_coordinated_turn_jacobian_batched() -> None:
    rng = np.random.default_rng(31)
    X = rng.standard_normal((7, 5)) * [100, 10, 100, 10, 0.2]
    X[0, 4] = 0.0
    dts = rng.uniform(0.05, 2.0, 7)
    J = CT.jacobian(X, dts)
    for i in range(7):
        np.testing.assert_allclose(J[i], CT.jacobian(X[i], float(dts[i])), rtol=1e-14, atol=1e-14,
                                   err_msg=f"seed=31 row {i}")


# --- radars -----------------------------------------------------------------------------------

RADAR2D = {
    "origin": {},
    "origin_rr": {"range_rate": True},
    "offset_heading": {"position": (300.0, -150.0), "heading_rad": 2.5},
    "offset_heading_rr": {"position": (300.0, -150.0), "heading_rad": -1.2, "range_rate": True},
}
STATES_2D = {
    "q1": np.array([1000.0, 20.0, 800.0, -15.0]),
    "behind": np.array([-1000.0, -5.0, 30.0, 40.0]),  # bearing near pi from the origin
    "close": np.array([310.0, 3.0, -140.0, -7.0]),
}


@pytest.mark.parametrize("state", list(STATES_2D), ids=list(STATES_2D))
@pytest.mark.parametrize("cfg", list(RADAR2D), ids=list(RADAR2D))
def test_radar2d_jacobian(cfg: str, state: str) -> None:
    kw = RADAR2D[cfg]
    R = [1.0, 1e-4, 0.25] if kw.get("range_rate") else [1.0, 1e-4]
    meas = Radar2D(R=R, **kw)
    x = STATES_2D[state]
    z0 = meas.h(x)
    # differences of h are wrapped so that a bearing near +-pi differentiates correctly
    Jfd = _fd(lambda s: meas.residual(meas.h(s), z0), x)
    _assert_jac(meas.jacobian(x), Jfd, 1e-6, f"Radar2D {cfg} at {state}")


RADAR3D = {
    "origin": {},
    "origin_rr": {"range_rate": True},
    "offset_heading_rr": {"position": (100.0, -50.0, 20.0), "heading_rad": 0.7, "range_rate": True},
}
STATES_3D = {
    "up": np.array([1000.0, 20.0, 800.0, -15.0, 300.0, 2.0]),
    "below": np.array([-500.0, 5.0, -20.0, 40.0, -150.0, -3.0]),
}


@pytest.mark.parametrize("state", list(STATES_3D), ids=list(STATES_3D))
@pytest.mark.parametrize("cfg", list(RADAR3D), ids=list(RADAR3D))
def test_radar3d_jacobian(cfg: str, state: str) -> None:
    kw = RADAR3D[cfg]
    R = [1.0, 1e-4, 1e-4, 0.25] if kw.get("range_rate") else [1.0, 1e-4, 1e-4]
    meas = Radar3D(R=R, **kw)
    x = STATES_3D[state]
    z0 = meas.h(x)
    Jfd = _fd(lambda s: meas.residual(meas.h(s), z0), x)
    _assert_jac(meas.jacobian(x), Jfd, 1e-6, f"Radar3D {cfg} at {state}")


def test_radar_jacobian_batched() -> None:
    rng = np.random.default_rng(8)
    X = rng.standard_normal((5, 6)) * [500, 10, 500, 10, 100, 2]
    for meas in (Radar3D(R=[1, 1e-4, 1e-4, 0.25], range_rate=True, position=(5, 6, 7)),):
        J = meas.jacobian(X)
        for i in range(5):
            np.testing.assert_allclose(J[i], meas.jacobian(X[i]), rtol=1e-14, err_msg=f"seed=8 {i}")
    X2 = X[:, :4]
    meas2 = Radar2D(R=[1, 1e-4, 0.25], range_rate=True, position=(5, 6), heading_rad=1.0)
    J2 = meas2.jacobian(X2)
    for i in range(5):
        np.testing.assert_allclose(J2[i], meas2.jacobian(X2[i]), rtol=1e-14, err_msg=f"seed=8 {i}")


# --- helix models -----------------------------------------------------------------------------

HELIX = {"rotation": HelixExact(), "document": HelixDoc()}
HELIX_STATES = {
    "start": np.array([0.0, 20.0, 0.0, 0.1, 0.5]),
    "elsewhere": np.array([-13.0, 7.0, 21.0, -0.4, 1.3]),
    "omega0": np.array([5.0, -3.0, 2.0, 0.0, 0.2]),
}


@pytest.mark.parametrize("dt", DTS, ids=[f"dt{d}" for d in DTS])
@pytest.mark.parametrize("state", list(HELIX_STATES), ids=list(HELIX_STATES))
@pytest.mark.parametrize("model", list(HELIX), ids=list(HELIX))
def test_helix_jacobian(model: str, state: str, dt: float) -> None:
    m = HELIX[model]
    x = HELIX_STATES[state]
    Jfd = _fd(lambda s: m.f(s, dt), x)
    _assert_jac(m.jacobian(x, dt), Jfd, 1e-6, f"helix {model} at {state} dt={dt}")


@pytest.mark.parametrize("range_rate", [False, True], ids=["range-bearing", "range-rate"])
def test_radar2d_h_of_a_stack_is_each_rows_numpy_formula(range_rate: bool) -> None:
    """Radar2D.h of a stack (N, M, n) (the batched gates': tracks by modes) is, row by row, the
    numpy formula of one state's measurement: range hypot(dx, dy), bearing wrap(arctan2(dy, dx)
    - heading), range rate (dx vx + dy vy) / r, bit for bit (its columns are filled in place)."""
    rng = np.random.default_rng(12)
    X = rng.standard_normal((7, 2, 4)) * [500, 10, 500, 10]
    X[0, 0, [0, 2]] = [5.0, 6.0 - 1e-3]  # at the sensor's position, nearly: a bearing near the wrap
    meas = Radar2D(R=[1, 1e-4, 0.25][: 3 if range_rate else 2], range_rate=range_rate, position=(5, 6),
                   heading_rad=1.0)
    Z = meas.h(X)
    assert Z.shape == (7, 2, 3 if range_rate else 2)
    for i in range(7):
        for j in range(2):
            x = X[i, j][None]  # a stack of one: the numpy path
            dx, dy = x[:, 0] - 5.0, x[:, 2] - 6.0
            r = np.hypot(dx, dy)
            want = [r, wrap_angle(np.arctan2(dy, dx) - 1.0)]
            if range_rate:
                want.append((dx * x[:, 1] + dy * x[:, 3]) / r)
            assert np.array_equal(Z[i, j], np.concatenate(want)), f"seed 12, row {i}, mode {j}"
