"""The fused filter step, `step(state, t_ns, z, model, R=)`, against predict then update.

- for every model with a compiled twin (CartesianPosition with and without a pose, Radar2D with
  and without range rate), with the model's R and a given R, validated or not, a run of steps
  equals predict then update bit for bit: the posterior, y, S, NIS, log-likelihood and t_ns;
- the paths it hands to the two calls give what the two calls give: a nonlinear motion model,
  a model without a compiled twin, z as a list, a control input;
- it refuses what the two calls refuse, with the same error class and message: a time step
  backwards, a non-finite prediction (check on only), a nonlinear measurement model in the KF
  (after predict's own checks); bad z and R: tests/core/test_step_kernels.py, beside update.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.gaussian import GaussianState, Update
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition
from fusion.core.motion import ConstantVelocity, CoordinatedTurn
from fusion.core.radar import Radar2D
from fusion.errors import ConfigError, NumericalError, TimeError

NAN = float("nan")
SEEDS = (0, 1)
DT_NS = 100_000_000


class PlainCartesian(CartesianPosition):
    """CartesianPosition without its compiled twin (the numpy path)."""


MODELS = {
    "cart_2d": lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.5, 2.0]),
    "cart_2d_posed": lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[[1.0, 0.3], [0.3, 2.0]],
                                               position=[120.0, -40.0], heading_rad=0.7),
    "cart_3d_posed": lambda: CartesianPosition(ndim_state=6, indices=(0, 2, 4), R=[1.0, 2.0, 3.0],
                                               position=[10.0, 20.0, 5.0], heading_rad=-1.1, pitch_rad=0.2),
    "radar": lambda: Radar2D(R=[25.0, 1e-4]),
    "radar_rr": lambda: Radar2D(R=[25.0, 1e-4, 0.25], range_rate=True, position=[-50.0, 80.0], heading_rad=-3.0),
    "plain_cart": lambda: PlainCartesian(ndim_state=4, indices=(0, 2), R=[0.5, 2.0]),
}


def _same(a: Update, b: Update) -> None:
    assert a.state.t_ns == b.state.t_ns
    for u, v in ((a.state.x, b.state.x), (a.state.P, b.state.P), (a.y, b.y), (a.S, b.S)):
        assert u.shape == v.shape and u.dtype == v.dtype
        np.testing.assert_array_equal(u, v)
    np.testing.assert_array_equal([a.nis, a.log_likelihood], [b.nis, b.log_likelihood])  # NaN == NaN


def _start(n: int, rng: np.random.Generator) -> GaussianState:
    x = rng.normal(0.0, 1.0, n)
    x[0] += 1000.0
    A = rng.standard_normal((n, n))
    return GaussianState.create(x, 10.0 * (A @ A.T + 0.5 * np.eye(n)), t_ns=0)


@pytest.mark.parametrize("seed", SEEDS, ids=[f"seed{s}" for s in SEEDS])
@pytest.mark.parametrize("explicit_R", (False, True), ids=["model_R", "given_R"])
@pytest.mark.parametrize("check", (True, False), ids=["check", "nocheck"])
@pytest.mark.parametrize("name", list(MODELS), ids=list(MODELS))
def test_step_equals_predict_then_update(name: str, check: bool, explicit_R: bool, seed: int) -> None:
    rng = np.random.default_rng(seed)
    meas = MODELS[name]()
    n = meas.ndim_state
    cls = KalmanFilter if meas.is_linear else ExtendedKalmanFilter
    f = cls(ConstantVelocity(ndim=n // 2, q=0.5), check=check)
    a = b = _start(n, rng)
    for k in range(30):
        t = a.t_ns + int(rng.integers(1, 3)) * DT_NS
        z = meas.h(f.predict(a, t).x) + rng.normal(0.0, 0.1, meas.ndim_meas)
        R = meas.R * (1.0 + k / 10.0) if explicit_R else None
        fused, two = f.step(a, t, z, meas, R=R), f.update(f.predict(b, t), z, meas, R=R)
        _same(fused, two)
        a, b = fused.state, two.state


def test_handed_to_the_two_calls() -> None:
    """A nonlinear motion model, z as a list, a control input: what predict then update give."""
    rng = np.random.default_rng(7)
    ct = ExtendedKalmanFilter(CoordinatedTurn(q_accel=0.5, q_turn=0.01))
    st = GaussianState.create([1000.0, 5.0, 200.0, 1.0, 0.05], np.eye(5) * 4.0)
    meas = Radar2D(R=[25.0, 1e-4], ndim_state=5)
    z = meas.h(st.x) + rng.normal(0.0, 0.1, 2)
    _same(ct.step(st, DT_NS, z, meas), ct.update(ct.predict(st, DT_NS), z, meas))
    kf = KalmanFilter(ConstantVelocity(ndim=2, q=0.5))
    cart = MODELS["cart_2d"]()
    s4 = _start(4, rng)
    _same(kf.step(s4, DT_NS, [1000.0, 0.5], cart), kf.update(kf.predict(s4, DT_NS), [1000.0, 0.5], cart))
    with pytest.raises(ConfigError, match="takes no control input"):
        kf.step(s4, DT_NS, np.array([1000.0, 0.5]), cart, u=[1.0, 1.0])


def test_step_refuses_time_nonfinite_and_nonlinear() -> None:
    kf = KalmanFilter(ConstantVelocity(ndim=1, q=1.0))
    meas = CartesianPosition(ndim_state=2, indices=(0,), R=[1.0])
    st = GaussianState.create([0.0, 0.0], np.eye(2), t_ns=DT_NS)
    with pytest.raises(TimeError):
        kf.step(st, 0, np.array([0.5]), meas)
    bad = GaussianState(np.array([NAN, 0.0]), np.eye(2), 0)
    with pytest.raises(NumericalError, match="prediction produced a non-finite state"):
        kf.step(bad, DT_NS, np.array([0.5]), meas)
    loose = KalmanFilter(ConstantVelocity(ndim=1, q=1.0), check=False)
    _same(loose.step(bad, DT_NS, np.array([0.5]), meas), loose.update(loose.predict(bad, DT_NS), np.array([0.5]), meas))
    assert np.isnan(loose.step(bad, DT_NS, np.array([0.5]), meas).state.x).all()
    radar = Radar2D(R=[1.0, 1e-4], ndim_state=4)
    kf2 = KalmanFilter(ConstantVelocity(ndim=2, q=1.0))
    s4 = GaussianState.create([1000.0, 0.0, 10.0, 0.0], np.eye(4), t_ns=DT_NS)
    with pytest.raises(TimeError):  # predict's check comes first, as in predict then update
        kf2.step(s4, 0, np.array([1000.0, 0.0]), radar)
    with pytest.raises(ConfigError, match="KalmanFilter needs a linear measurement model"):
        kf2.step(s4, 2 * DT_NS, np.array([1000.0, 0.0]), radar)
