"""Mode sets: constant velocity in the coordinated-turn state, and an IMM of CV + CT built by
`build_imm` that beats CV alone on a target that flies straight, turns, and flies straight."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.imm import IMM
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition
from fusion.core.modes import ConstantVelocityWithTurnRate, Mode, build_imm
from fusion.core.motion import ConstantVelocity, CoordinatedTurn
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import ConfigError


def _fd(fun, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = h * max(1.0, abs(x[j]))
        cols.append((fun(x + e) - fun(x - e)) / (2 * e[j]))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("dt", (0.0, 0.1, 2.0), ids=["dt0", "dt0.1", "dt2"])
def test_cv_with_turn_rate_is_cv_with_omega_held(dt: float) -> None:
    m = ConstantVelocityWithTurnRate(q_accel=0.7, q_turn=0.05)
    cv = ConstantVelocity(ndim=2, q=0.7)
    x = np.array([120.0, 14.0, -40.0, -9.0, 0.3])
    fx = m.f(x, dt)
    np.testing.assert_allclose(fx[:4], cv.f(x[:4], dt), rtol=1e-15)
    assert fx[4] == x[4]  # held, and it does not turn the velocity
    np.testing.assert_allclose(m.jacobian(x, dt), _fd(lambda s: m.f(s, dt), x), atol=1e-8)
    Q = m.Q(x, dt)
    np.testing.assert_allclose(Q[:4, :4], cv.Q(x[:4], dt), rtol=1e-15)
    assert Q[4, 4] == pytest.approx(0.05**2 * dt) and not Q[4, :4].any()
    # batched over a stack of states and steps
    X = np.stack([x, x + 1.0])
    dts = np.array([dt, 0.5])
    FX = m.f(X, dts)
    np.testing.assert_allclose(FX[1], m.f(X[1], 0.5), rtol=1e-15)
    np.testing.assert_allclose(m.F(dts)[1], m.F(0.5), rtol=1e-15)


def test_ct_jacobian_by_finite_differences() -> None:
    """(test_jacobians.py checks it over a grid of turn rates; here at one turn state as used below)"""
    ct = CoordinatedTurn(q_accel=0.3, q_turn=0.05)
    x = np.array([300.0, 10.0, 200.0, 11.0, 0.15])
    for dt in (0.5, 1.0):
        np.testing.assert_allclose(ct.jacobian(x, dt), _fd(lambda s, dt=dt: ct.f(s, dt), x, 1e-7),
                                   rtol=1e-6, atol=1e-6)


def test_build_imm() -> None:
    imm = build_imm([Mode("cv", 0.3, 20.0, 0.0), Mode("ct", 0.3, 10.0, 0.05)])
    assert isinstance(imm, IMM) and imm.ndim_state == 5
    assert isinstance(imm.filters[0].motion, ConstantVelocityWithTurnRate)
    assert isinstance(imm.filters[1].motion, CoordinatedTurn)
    np.testing.assert_allclose(imm.rates, [[-0.05, 0.05], [0.1, -0.1]])
    cv3 = build_imm([Mode("cv", 0.1, 5.0), Mode("cv", 3.0, 2.0)], ndim=3, filter="ukf")
    assert cv3.ndim_state == 6 and all(isinstance(f, UnscentedKalmanFilter) for f in cv3.filters)
    assert isinstance(cv3.filters[0].motion, ConstantVelocity)
    three = build_imm([Mode("cv", 0.1, 5.0), Mode("cv", 3.0, 2.0), Mode("ct", 0.3, 4.0, 0.1)])
    np.testing.assert_allclose(three.rates[2], [0.125, 0.125, -0.25])


BAD = {
    "one_mode": ([Mode("cv", 0.1, 5.0)], {}, "at least two modes"),
    "ct_3d": ([Mode("cv", 0.1, 5.0), Mode("ct", 0.1, 5.0, 0.1)], {"ndim": 3}, "2-D"),
    "kind": ([Mode("cv", 0.1, 5.0), Mode("ca", 0.1, 5.0)], {}, "unknown mode kind"),  # type: ignore[arg-type]
    "filter": ([Mode("cv", 0.1, 5.0), Mode("cv", 1.0, 5.0)], {"filter": "pf"}, "unknown filter"),
    "sojourn": ([Mode("cv", 0.1, 5.0), Mode("cv", 1.0, -1.0)], {}, "> 0 seconds"),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_build_imm_refuses(case: str) -> None:
    modes, kw, match = BAD[case]
    with pytest.raises(ConfigError, match=match):
        build_imm(modes, **kw)


# --- straight, turn, straight -------------------------------------------------------------------

DT_S, STD_M = 0.5, 5.0
T_TURN = (20.0, 35.0)  # turning at OMEGA between these times (2.25 rad)
OMEGA, SPEED = 0.15, 15.0


def _truth() -> tuple[np.ndarray, np.ndarray]:
    """[px, vx, py, vy, omega] every DT_S for 55 s, exact kinematics; times in seconds."""
    ct = CoordinatedTurn(q_accel=0.0, q_turn=0.0)
    x = np.array([0.0, SPEED, 0.0, 0.0, 0.0])
    t, out = [], []
    for k in range(1, 111):
        tk = k * DT_S
        x = x.copy()
        x[4] = OMEGA if T_TURN[0] < tk <= T_TURN[1] else 0.0  # the rate over the step ending at tk
        x = ct.f(x, DT_S)
        t.append(tk)
        out.append(x)
    return np.array(t), np.array(out)


def _run(filt, x0: np.ndarray, P0: np.ndarray, z: np.ndarray, t_s: np.ndarray, meas) -> tuple[np.ndarray, list]:
    st = filt.initial(x0, P0, t_ns=0)
    xs, mus = [], []
    for k in range(len(t_s)):
        st = filt.update(filt.predict(st, round(t_s[k] * 1e9)), z[k], meas).state
        xs.append(st.x)
        mus.append(getattr(st, "mu", None))
    return np.array(xs), mus


SEEDS = (0, 1, 2, 3)


@pytest.mark.parametrize("filter_kind", ("ekf", "ukf"))
def test_cv_ct_imm_beats_cv_through_a_turn(filter_kind: str) -> None:
    t_s, truth = _truth()
    rmse_cv, rmse_imm, mu_before, mu_turn = [], [], [], []
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        z = truth[:, [0, 2]] + STD_M * rng.standard_normal((len(t_s), 2))
        m4 = CartesianPosition(ndim_state=4, indices=(0, 2), R=[STD_M**2] * 2)
        m5 = CartesianPosition(ndim_state=5, indices=(0, 2), R=[STD_M**2] * 2)
        x0 = np.array([0.0, SPEED, 0.0, 0.0])
        P0 = np.diag([STD_M**2, 4.0, STD_M**2, 4.0])
        x_cv, _ = _run(KalmanFilter(ConstantVelocity(ndim=2, q=0.3)), x0, P0, z, t_s, m4)
        imm = build_imm([Mode("cv", 0.3, 30.0), Mode("ct", 0.3, 15.0, 0.05)], filter=filter_kind)
        P05 = np.diag([STD_M**2, 4.0, STD_M**2, 4.0, 0.1**2])
        x_imm, mus = _run(imm, np.append(x0, 0.0), P05, z, t_s, m5)
        after = t_s > 5.0
        e_cv = truth[after][:, [0, 2]] - x_cv[after][:, [0, 2]]
        e_imm = truth[after][:, [0, 2]] - x_imm[after][:, [0, 2]]
        rmse_cv.append(float(np.sqrt(np.mean(np.sum(e_cv**2, axis=1)))))
        rmse_imm.append(float(np.sqrt(np.mean(np.sum(e_imm**2, axis=1)))))
        mu_ct = np.array([m[1] for m in mus])
        mu_before.append(float(mu_ct[(t_s > 5.0) & (t_s <= T_TURN[0])].mean()))
        mu_turn.append(float(mu_ct[(t_s > T_TURN[0] + 3.0) & (t_s <= T_TURN[1])].mean()))
    msg = (f"{filter_kind} seeds={SEEDS}: position RMSE CV {np.round(rmse_cv, 2)}, CV+CT IMM "
           f"{np.round(rmse_imm, 2)}; P(CT) before the turn {np.round(mu_before, 2)}, "
           f"in it {np.round(mu_turn, 2)}")
    # measured (EKF / UKF): RMSE CV 10.8-11.7 m (it lags in the turn; raw measurements ~7 m),
    # IMM 2.8-4.4 / 2.7-4.2 m; P(CT) 0.13-0.17 before the turn, 0.67-0.79 from 3 s into it
    assert np.mean(rmse_imm) < 0.6 * np.mean(rmse_cv), msg
    assert all(b > 2.0 * a for a, b in zip(mu_before, mu_turn, strict=True)), msg
    assert np.mean(mu_turn) > 0.6, msg


def test_ekf_of_cv_with_turn_rate_equals_cv_kf_on_position() -> None:
    """The omega component is decoupled: the 5-state EKF equals the 4-state KF on the rest."""
    rng = np.random.default_rng(4)
    m4 = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    m5 = CartesianPosition(ndim_state=5, indices=(0, 2), R=[1.0, 1.0])
    kf, ekf = KalmanFilter(ConstantVelocity(ndim=2, q=0.5)), ExtendedKalmanFilter(
        ConstantVelocityWithTurnRate(q_accel=0.5, q_turn=0.1))
    s4 = kf.initial(np.zeros(4), np.eye(4), t_ns=0)
    s5 = ekf.initial(np.zeros(5), np.eye(5), t_ns=0)
    for k in range(1, 30):
        z = rng.standard_normal(2) + k
        s4 = kf.update(kf.predict(s4, k * 300_000_000), z, m4).state
        s5 = ekf.update(ekf.predict(s5, k * 300_000_000), z, m5).state
    np.testing.assert_allclose(s5.x[:4], s4.x, rtol=1e-12, atol=1e-12, err_msg="seed=4")
    np.testing.assert_allclose(s5.P[:4, :4], s4.P, rtol=1e-12, atol=1e-12, err_msg="seed=4")
    assert s5.P[4, 4] == pytest.approx(1.0 + 0.1**2 * 29 * 0.3)
