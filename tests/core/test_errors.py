"""Bad input raises typed errors from fusion.errors with messages that name the culprit;
dt = 0 is a valid (identity) prediction."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.gaussian import GaussianState
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition, Radar2D, Radar3D
from fusion.core.motion import (
    ConstantAcceleration,
    ConstantVelocity,
    CoordinatedTurn,
    LinearModel,
)
from fusion.core.ukf import UnscentedKalmanFilter
from fusion.errors import (
    ConfigError,
    FusionError,
    InputError,
    NonFiniteError,
    NotPositiveDefiniteError,
    ShapeError,
    TimeError,
)

NAN, INF = float("nan"), float("inf")
CV1 = ConstantVelocity(ndim=1, q=1.0)
POS1 = CartesianPosition(ndim_state=2, indices=(0,), R=[1.0])


def _filters():
    return {
        "kf": KalmanFilter(CV1),
        "ekf": ExtendedKalmanFilter(CV1),
        "ukf": UnscentedKalmanFilter(CV1),
    }


FILTER_IDS = ("kf", "ekf", "ukf")


def _state(t_ns: int = 0) -> GaussianState:
    return GaussianState.create([0.0, 1.0], np.eye(2), t_ns=t_ns)


# --- GaussianState.create ---------------------------------------------------------------------

CREATE_CASES = {
    "x_matrix": ([[1.0, 2.0]], np.eye(2), ShapeError, r"x must be a vector, got shape \(1, 2\)"),
    "x_nan": ([1.0, NAN], np.eye(2), NonFiniteError, "x holds NaN or inf"),
    "x_inf": ([INF, 0.0], np.eye(2), NonFiniteError, "x holds NaN or inf"),
    "P_wrong_size": ([1.0, 2.0], np.eye(3), ShapeError,
                     r"P must have shape \(2, 2\), got \(3, 3\)"),
    "P_vector": ([1.0, 2.0], [1.0, 1.0], ShapeError, r"P must be a matrix, got shape \(2,\)"),
    "P_nan": ([1.0, 2.0], [[1.0, NAN], [NAN, 1.0]], NonFiniteError, "P holds NaN or inf"),
    "P_inf": ([1.0, 2.0], [[INF, 0.0], [0.0, 1.0]], NonFiniteError, "P holds NaN or inf"),
    "P_indefinite": ([1.0, 2.0], [[1.0, 0.0], [0.0, -1.0]], NotPositiveDefiniteError,
                     r"P is not positive definite \(smallest eigenvalue -1\)"),
    "P_singular": ([1.0, 2.0], [[1.0, 1.0], [1.0, 1.0]], NotPositiveDefiniteError,
                   "P is not positive definite"),
    "P_asymmetric": ([1.0, 2.0], [[1.0, 0.5], [0.4, 1.0]], NotPositiveDefiniteError,
                     "P is not symmetric"),
}


@pytest.mark.parametrize("case", list(CREATE_CASES), ids=list(CREATE_CASES))
def test_gaussian_state_create_refuses(case: str) -> None:
    x, P, err, match = CREATE_CASES[case]
    with pytest.raises(err, match=match) as info:
        GaussianState.create(x, P)
    assert isinstance(info.value, InputError) and isinstance(info.value, ValueError)


@pytest.mark.parametrize("kind", FILTER_IDS, ids=FILTER_IDS)
def test_initial_wrong_dimension(kind: str) -> None:
    with pytest.raises(ShapeError, match="3"):
        _filters()[kind].initial([0.0, 1.0, 2.0], np.eye(3), t_ns=0)


# --- update: z and R --------------------------------------------------------------------------

UPDATE_CASES = {
    "z_too_long": ({"z": [1.0, 2.0]}, ShapeError, "z must have length 1, got 2"),
    "z_matrix": ({"z": [[1.0]]}, ShapeError, r"z must be a vector, got shape \(1, 1\)"),
    "z_nan": ({"z": [NAN]}, NonFiniteError, "z holds NaN or inf"),
    "z_inf": ({"z": [-INF]}, NonFiniteError, "z holds NaN or inf"),
    "R_wrong_shape": ({"R": np.eye(2)}, ShapeError, r"R must have shape \(1, 1\), got \(2, 2\)"),
    "R_nan": ({"R": [[NAN]]}, NonFiniteError, "R holds NaN or inf"),
    "R_inf": ({"R": [[INF]]}, NonFiniteError, "R holds NaN or inf"),
    "R_negative": ({"R": [[-1.0]]}, NotPositiveDefiniteError, "R is not positive definite"),
    "R_zero": ({"R": [[0.0]]}, NotPositiveDefiniteError, "R is not positive definite"),
}


@pytest.mark.parametrize("kind", FILTER_IDS, ids=FILTER_IDS)
@pytest.mark.parametrize("case", list(UPDATE_CASES), ids=list(UPDATE_CASES))
def test_update_refuses(case: str, kind: str) -> None:
    kw, err, match = UPDATE_CASES[case]
    z = kw.get("z", [1.0])
    with pytest.raises(err, match=match):
        _filters()[kind].update(_state(), z, POS1, R=kw.get("R"))


def test_update_radar_R_not_positive_definite() -> None:
    ekf = ExtendedKalmanFilter(ConstantVelocity(ndim=2, q=1.0))
    st = GaussianState.create([1000.0, 0.0, 10.0, 0.0], np.eye(4))
    with pytest.raises(NotPositiveDefiniteError, match="R is not positive definite"):
        ekf.update(st, [1000.0, 0.01], Radar2D(R=[1.0, 1e-4]), R=[[1.0, 2.0], [2.0, 1.0]])


# --- model constructors -----------------------------------------------------------------------

CONSTRUCTOR_CASES = {
    "cartesian_R_negative": (lambda: CartesianPosition(ndim_state=2, indices=(0,), R=[-1.0]),
                             NotPositiveDefiniteError, "R is not positive definite"),
    "cartesian_R_zero": (lambda: CartesianPosition(ndim_state=2, indices=(0,), R=[0.0]),
                         NotPositiveDefiniteError, "R is not positive definite"),
    "cartesian_R_nan": (lambda: CartesianPosition(ndim_state=2, indices=(0,), R=[NAN]),
                        NonFiniteError, "R holds NaN or inf"),
    "cartesian_R_shape": (lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0]),
                          ShapeError, r"R must have shape \(2, 2\)"),
    "cartesian_bad_index": (lambda: CartesianPosition(ndim_state=2, indices=(2,), R=[1.0]),
                            ConfigError, r"indices \(2,\) must pick components of a 2-state"),
    "radar2d_R_indefinite": (lambda: Radar2D(R=[[1.0, 2.0], [2.0, 1.0]]),
                             NotPositiveDefiniteError, "R is not positive definite"),
    "radar2d_R_shape": (lambda: Radar2D(R=[1.0, 1.0, 1.0]), ShapeError,
                        r"R must have shape \(2, 2\), got \(3, 3\)"),
    "radar2d_rr_R_shape": (lambda: Radar2D(R=[1.0, 1.0], range_rate=True), ShapeError,
                           r"R must have shape \(3, 3\)"),
    "radar2d_position_nan": (lambda: Radar2D(R=[1.0, 1.0], position=[0.0, NAN]),
                             NonFiniteError, "position holds NaN or inf"),
    "radar2d_position_shape": (lambda: Radar2D(R=[1.0, 1.0], position=[0.0, 0.0, 0.0]),
                               ShapeError, "position must have length 2"),
    "radar3d_R_inf": (lambda: Radar3D(R=[1.0, INF, 1.0]), NonFiniteError, "R holds NaN or inf"),
    "radar3d_R_negative": (lambda: Radar3D(R=[1.0, 1.0, -1.0]), NotPositiveDefiniteError,
                           "R is not positive definite"),
    "cv_q_negative": (lambda: ConstantVelocity(ndim=2, q=-1.0), ConfigError,
                      "process noise q must be finite and >= 0, got -1"),
    "cv_q_nan": (lambda: ConstantVelocity(ndim=2, q=NAN), ConfigError,
                 "process noise q must be finite and >= 0"),
    "cv_ndim4": (lambda: ConstantVelocity(ndim=4, q=1.0), ConfigError, "ndim must be 1, 2 or 3"),
    "ca_q_inf": (lambda: ConstantAcceleration(ndim=1, q=INF), ConfigError,
                 "process noise q must be finite"),
    "ct_q_negative": (lambda: CoordinatedTurn(q_accel=1.0, q_turn=-1.0), ConfigError,
                      "q_accel and q_turn must be finite and >= 0"),
    "linear_Q_indefinite": (
        lambda: LinearModel(F=lambda dt: np.eye(2), Q=lambda dt: -np.eye(2), position_indices=(0,)),
        NotPositiveDefiniteError, r"Q\(1.0\) is not positive semi-definite"),
    "linear_F_not_square": (
        lambda: LinearModel(F=lambda dt: np.ones((2, 3)), Q=lambda dt: np.eye(2),
                            position_indices=(0,)),
        ConfigError, r"F\(dt\) must return a square matrix, got shape \(2, 3\)"),
}


@pytest.mark.parametrize("case", list(CONSTRUCTOR_CASES), ids=list(CONSTRUCTOR_CASES))
def test_model_constructor_refuses(case: str) -> None:
    make, err, match = CONSTRUCTOR_CASES[case]
    with pytest.raises(err, match=match) as info:
        make()
    assert isinstance(info.value, FusionError)


@pytest.mark.parametrize("heading", [NAN, INF], ids=["nan", "inf"])
@pytest.mark.parametrize("cls", [Radar2D, Radar3D], ids=["radar2d", "radar3d"])
def test_radar_heading_must_be_finite(cls, heading: float) -> None:
    """Before the fix a NaN heading was accepted and silently made every update NaN."""
    R = [1.0, 1.0] if cls is Radar2D else [1.0, 1.0, 1.0]
    with pytest.raises(NonFiniteError, match="heading_rad holds NaN or inf"):
        cls(R=R, heading_rad=heading)


# --- time -------------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", FILTER_IDS, ids=FILTER_IDS)
def test_predict_backwards_is_time_error(kind: str) -> None:
    f = _filters()[kind]
    st = f.predict(_state(t_ns=1_000), 2_000_000)
    with pytest.raises(TimeError, match=r"negative time step: from t_ns=2000000 to t_ns=1999999"):
        f.predict(st, 1_999_999)


MODELS_DT0 = {
    "cv1": (ConstantVelocity(ndim=1, q=1.0), np.array([1.0, 2.0])),
    "ca2": (ConstantAcceleration(ndim=2, q=0.5), np.arange(6.0)),
    "ct": (CoordinatedTurn(q_accel=1.0, q_turn=0.1), np.array([10.0, 3.0, -5.0, 4.0, 0.2])),
}


@pytest.mark.parametrize("kind", FILTER_IDS, ids=FILTER_IDS)
@pytest.mark.parametrize("model", list(MODELS_DT0), ids=list(MODELS_DT0))
def test_predict_dt_zero_is_identity(model: str, kind: str) -> None:
    motion, x = MODELS_DT0[model]
    if kind == "kf" and not motion.is_linear:
        pytest.skip("the KF takes linear models only (see test_kf_refuses_nonlinear)")
    cls = {"kf": KalmanFilter, "ekf": ExtendedKalmanFilter, "ukf": UnscentedKalmanFilter}[kind]
    f = cls(motion)
    rng = np.random.default_rng(5)
    A = rng.standard_normal((x.size, x.size))
    P = A @ A.T + x.size * np.eye(x.size)
    np.testing.assert_array_equal(motion.Q(x, 0.0), 0.0)
    st = f.initial(x, P, t_ns=123_456_789)
    out = f.predict(st, 123_456_789)
    assert out.t_ns == st.t_ns
    np.testing.assert_allclose(out.x, x, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(out.P, P, rtol=1e-12, atol=1e-12)


# --- configuration ----------------------------------------------------------------------------

def test_kf_refuses_nonlinear_motion() -> None:
    match = "KalmanFilter needs a linear motion model, got CoordinatedTurn"
    with pytest.raises(ConfigError, match=match):
        KalmanFilter(CoordinatedTurn(q_accel=1.0, q_turn=0.1))


@pytest.mark.parametrize("meas", [Radar2D(R=[1.0, 1e-4]), Radar3D(R=[1.0, 1e-4, 1e-4])],
                         ids=["radar2d", "radar3d"])
def test_kf_refuses_nonlinear_measurement(meas) -> None:
    kf = KalmanFilter(ConstantVelocity(ndim=3, q=1.0))
    st = kf.initial(np.ones(6), np.eye(6), t_ns=0)
    match = f"needs a linear measurement model, got {type(meas).__name__}"
    with pytest.raises(ConfigError, match=match):
        kf.update(st, np.ones(meas.ndim_meas), meas)


@pytest.mark.parametrize("kind", FILTER_IDS, ids=FILTER_IDS)
def test_control_input_without_B(kind: str) -> None:
    with pytest.raises(ConfigError, match="ConstantVelocity takes no control input"):
        _filters()[kind].predict(_state(), 1_000, u=[1.0])
