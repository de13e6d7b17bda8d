"""The compiled single-state steps (fusion.core.compiled_step) against the numpy path.

- update: CartesianPosition (with and without a pose) and Radar2D (with and without range rate,
  offset and turned sensors, explicit R) agree with the numpy path to 1e-12; the numpy path is
  reached through the public API (z given as a list, or a subclass of the model, which has no
  compiled twin);
- predict: equals the numpy reference predict_arrays for every linear model, over many dt;
- the checks still refuse what they refused, with the same error class and message: NaN or
  inf in z, z of the wrong length, R asymmetric, not positive definite or non-finite, and a
  state whose S is not positive definite; update and the fused step alike;
- the angle wrap of the kernel is wrap_angle_scalar, at the +-pi edge too;
- the F, Q cache holds read-only copies and stays bounded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.core import compiled_step
from fusion.core.gaussian import GaussianState
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter, predict_arrays
from fusion.core.measurement import KERNEL_NONE, CartesianPosition, wrap_angle_scalar
from fusion.core.motion import ConstantAcceleration, ConstantVelocity, LinearModel
from fusion.core.radar import Radar2D
from fusion.core.transitions import TransitionCache
from fusion.errors import NonFiniteError, NotPositiveDefiniteError, NumericalError, ShapeError

SEEDS = (0, 1, 2)


def _spd(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + 0.5 * np.eye(n))


class PlainRadar2D(Radar2D):
    """Radar2D without its compiled twin (a subclass): the numpy path."""


class PlainCartesian(CartesianPosition):
    """CartesianPosition without its compiled twin."""


MODELS = {
    "cart_2d": lambda cls: cls(ndim_state=4, indices=(0, 2), R=[0.5, 2.0]),
    "cart_1d": lambda cls: cls(ndim_state=4, indices=(2,), R=[0.3]),
    "cart_2d_posed": lambda cls: cls(ndim_state=4, indices=(0, 2), R=[[1.0, 0.3], [0.3, 2.0]],
                                     position=[120.0, -40.0], heading_rad=0.7),
    "cart_3d_posed": lambda cls: cls(ndim_state=6, indices=(0, 2, 4), R=[1.0, 2.0, 3.0],
                                     position=[10.0, 20.0, 5.0], heading_rad=-1.1, pitch_rad=0.2,
                                     roll_rad=0.05),
    "radar": lambda cls: cls(R=[25.0, 1e-4]),
    "radar_offset_turned": lambda cls: cls(R=[[25.0, 0.001], [0.001, 1e-4]], position=[300.0, -200.0],
                                           heading_rad=2.5),
    "radar_rr": lambda cls: cls(R=[25.0, 1e-4, 0.25], range_rate=True, position=[-50.0, 80.0],
                                heading_rad=-3.0),
}
PLAIN = {"cart": PlainCartesian, "radar": PlainRadar2D}


def _pair(name: str):
    fast_cls = Radar2D if name.startswith("radar") else CartesianPosition
    return MODELS[name](fast_cls), MODELS[name](PLAIN[name.split("_")[0]])


def _state(rng: np.random.Generator, n: int) -> GaussianState:
    x = rng.normal(0.0, 1.0, n)
    x[0] += 1000.0  # away from a radar at (or near) the origin
    return GaussianState.create(x, _spd(rng, n, 10.0), t_ns=0)


@pytest.mark.parametrize("seed", SEEDS, ids=[f"seed{s}" for s in SEEDS])
@pytest.mark.parametrize("explicit_R", (False, True), ids=["model_R", "given_R"])
@pytest.mark.parametrize("check", (True, False), ids=["check", "nocheck"])
@pytest.mark.parametrize("name", list(MODELS), ids=list(MODELS))
def test_update_agrees_with_numpy_path(name: str, check: bool, explicit_R: bool, seed: int) -> None:
    rng = np.random.default_rng(seed)
    fast, plain = _pair(name)
    assert fast.kernel_kind != KERNEL_NONE and plain.kernel_kind == KERNEL_NONE
    n = fast.ndim_state if hasattr(fast, "indices") else 4
    ekf = ExtendedKalmanFilter(ConstantVelocity(ndim=n // 2, q=0.1), check=check)
    st = _state(rng, n)
    z = fast.h(st.x) + rng.normal(0.0, 0.1, fast.ndim_meas)
    R = _spd(rng, fast.ndim_meas, 0.1) if explicit_R else None
    a = ekf.update(st, z, fast, R=R)
    for b in (ekf.update(st, z, plain, R=R), ekf.update(st, z.tolist(), fast, R=None if R is None else R.tolist())):
        np.testing.assert_allclose(a.state.x, b.state.x, rtol=1e-12, atol=1e-12 * np.abs(b.state.x).max())
        np.testing.assert_allclose(a.state.P, b.state.P, rtol=1e-12, atol=1e-12 * np.abs(b.state.P).max())
        np.testing.assert_allclose(a.y, b.y, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a.S, b.S, rtol=1e-12)
        assert a.nis == pytest.approx(b.nis, rel=1e-12, abs=1e-12)
        assert a.log_likelihood == pytest.approx(b.log_likelihood, rel=1e-12)
        assert a.state.t_ns == b.state.t_ns


MOTIONS = {
    "cv1": ConstantVelocity(ndim=1, q=0.5),
    "cv2": ConstantVelocity(ndim=2, q=0.1),
    "ca3": ConstantAcceleration(ndim=3, q=0.2),
    "linear_user": LinearModel(F=lambda dt: np.array([[1.0, dt], [0.0, 0.9]]),
                               Q=lambda dt: np.array([[dt, 0.0], [0.0, 2 * dt]]), position_indices=(0,)),
}


@pytest.mark.parametrize("name", list(MOTIONS), ids=list(MOTIONS))
def test_predict_equals_numpy_reference(name: str) -> None:
    motion = MOTIONS[name]
    rng = np.random.default_rng(5)
    kf = KalmanFilter(motion)
    n = motion.ndim_state
    st = GaussianState.create(rng.normal(size=n), _spd(rng, n), t_ns=1_000)
    for dt_ns in (0, 1, 50_000_000, 100_000_000, 50_000_000, 2_500_000_000, 100_000_000):
        dt = dt_ns / 1e9
        pred = kf.predict(st, st.t_ns + dt_ns)
        x, P = predict_arrays(st.x, st.P, motion.F(dt), motion.Q_dt(dt))
        np.testing.assert_allclose(pred.x, x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(pred.P, P, rtol=1e-12, atol=1e-12)
        assert pred.t_ns == st.t_ns + dt_ns and type(pred.t_ns) is int


def test_long_run_equals_numpy_path() -> None:
    """200 radar steps through both paths: still equal to 1e-12 relative."""
    rng = np.random.default_rng(11)
    fast, plain = _pair("radar_offset_turned")
    ekf = ExtendedKalmanFilter(ConstantVelocity(ndim=2, q=0.5))
    a = b = GaussianState.create([1000.0, 5.0, 500.0, -3.0], np.diag([100.0, 4.0, 100.0, 4.0]))
    truth = np.array([1000.0, 5.0, 500.0, -3.0])
    for k in range(200):
        truth = truth + 0.1 * np.array([truth[1], 0.0, truth[3], 0.0])
        z = fast.h(truth) + rng.normal(0.0, [5.0, 0.01])
        t = (k + 1) * 100_000_000
        a = ekf.update(ekf.predict(a, t), z, fast).state
        b = ekf.update(ekf.predict(b, t), z, plain).state
    np.testing.assert_allclose(a.x, b.x, rtol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-10, atol=1e-12 * np.abs(b.P).max())


NAN, INF = float("nan"), float("inf")
REFUSED = {
    "z_nan": (np.array([1000.0, NAN]), None, NonFiniteError, "z holds NaN or inf"),
    "z_inf": (np.array([INF, 0.0]), None, NonFiniteError, "z holds NaN or inf"),
    "z_long": (np.array([1000.0, 0.0, 1.0]), None, ShapeError, "z must have length 2, got 3"),
    "R_asymmetric": (np.array([1000.0, 0.0]), np.array([[1.0, 0.5], [0.4, 1.0]]), NotPositiveDefiniteError,
                     "R is not symmetric"),
    "R_indefinite": (np.array([1000.0, 0.0]), np.array([[1.0, 2.0], [2.0, 1.0]]), NotPositiveDefiniteError,
                     "R is not positive definite"),
    "R_zero": (np.array([1000.0, 0.0]), np.zeros((2, 2)), NotPositiveDefiniteError, "R is not positive definite"),
    "R_nan": (np.array([1000.0, 0.0]), np.array([[1.0, NAN], [NAN, 1.0]]), NonFiniteError, "R holds NaN or inf"),
    "R_shape": (np.array([1000.0, 0.0]), np.eye(3), ShapeError, r"R must have shape \(2, 2\)"),
}


@pytest.mark.parametrize("model", ("cart", "radar"), ids=("cart", "radar"))
@pytest.mark.parametrize("case", list(REFUSED), ids=list(REFUSED))
def test_checks_refuse_on_the_compiled_path(case: str, model: str) -> None:
    z, R, err, match = REFUSED[case]
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0]) if model == "cart" else Radar2D(R=[1.0, 1e-4])
    ekf = ExtendedKalmanFilter(ConstantVelocity(ndim=2, q=1.0))
    st = GaussianState.create([1000.0, 0.0, 10.0, 0.0], np.eye(4))
    with pytest.raises(err, match=match):
        ekf.update(st, z, meas, R=R)
    with pytest.raises(err, match=match):  # the fused step (tests/core/test_filter_step.py) too
        ekf.step(st, 1_000_000, z, meas, R=R)


def test_S_not_positive_definite_is_numerical_error() -> None:
    """A covariance P that is not positive definite (built without create) with a tiny R."""
    kf = KalmanFilter(ConstantVelocity(ndim=1, q=1.0))
    meas = CartesianPosition(ndim_state=2, indices=(0,), R=[1e-6])
    st = GaussianState(np.zeros(2), np.array([[-1.0, 0.0], [0.0, 1.0]]), 0)
    with pytest.raises(NumericalError, match="not positive definite"):
        kf.update(st, np.array([0.5]), meas)


def test_nonfinite_prediction_refused_with_check_only() -> None:
    kf = KalmanFilter(ConstantVelocity(ndim=1, q=1.0))
    st = GaussianState(np.array([NAN, 0.0]), np.eye(2), 0)
    with pytest.raises(NumericalError, match="prediction produced a non-finite state"):
        kf.predict(st, 1_000)
    assert np.isnan(KalmanFilter(ConstantVelocity(ndim=1, q=1.0), check=False).predict(st, 1_000).x[0])


def test_nocheck_does_not_check_z() -> None:
    """check=False keeps what it did before: NaN in, NaN out, no error."""
    kf = KalmanFilter(ConstantVelocity(ndim=1, q=1.0), check=False)
    meas = CartesianPosition(ndim_state=2, indices=(0,), R=[1.0])
    up = kf.update(GaussianState.create([0.0, 0.0], np.eye(2)), np.array([NAN]), meas)
    assert np.isnan(up.state.x).all()


EDGES = (0.0, math.pi, -math.pi, math.pi - 1e-12, -math.pi + 1e-12, math.pi + 1e-12, 3 * math.pi,
         -3 * math.pi, 7.0, -7.0, 1e6, -1e6, 2 * math.pi, -2 * math.pi, math.nextafter(math.pi, 4.0))


@pytest.mark.parametrize("a", EDGES, ids=[f"{a!r}" for a in EDGES])
def test_kernel_wrap_is_wrap_angle_scalar(a: float) -> None:
    assert compiled_step.wrap(a) == wrap_angle_scalar(a)


def test_subclass_has_no_compiled_twin_unless_it_says_so() -> None:
    class Opted(Radar2D):
        kernel_kind = Radar2D.kernel_kind

    assert PlainRadar2D.kernel_kind == KERNEL_NONE and PlainCartesian.kernel_kind == KERNEL_NONE
    assert Opted.kernel_kind == Radar2D.kernel_kind


def test_transition_cache_read_only_and_bounded() -> None:
    cv = ConstantVelocity(ndim=2, q=0.3)
    cache = TransitionCache(cv, max_entries=4)
    FQ = cache[0.1]
    np.testing.assert_array_equal(FQ[0], cv.F(0.1))
    np.testing.assert_array_equal(FQ[1], cv.Q_dt(0.1))
    assert cache[0.1] is FQ and not FQ.flags.writeable
    for k in range(10):
        cache[0.01 * k]
    assert len(cache) <= 4


def test_transition_cache_refuses_wrong_shape() -> None:
    bad = LinearModel(F=lambda dt: np.eye(2), Q=lambda dt: np.eye(2) if dt == 1.0 else np.eye(3),
                      position_indices=(0,))
    with pytest.raises(ShapeError, match=r"must be 2 x 2"):
        TransitionCache(bad)[0.5]
