"""User-defined models loaded by import path (issue #12 item 2): the helix models load and
check out; a model with a wrong Jacobian, wrong shapes or NaN is refused with a ConfigError that
names the model and what is wrong."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.checks import Array
from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import CartesianPosition, MeasurementModel, Radar2D, Radar3D
from fusion.core.motion import ConstantVelocity, CoordinatedTurn, MotionModel
from fusion.errors import ConfigError
from fusion.models.helix import HelixDoc, HelixExact
from fusion.models.loader import check_model, load_model
from fusion.scenarios import reference, run_reference


def test_loads_both_helix_models() -> None:
    exact = load_model("fusion.models.helix:HelixExact", {"q_pos": 0.2})
    assert isinstance(exact, HelixExact) and exact.q_pos == 0.2
    doc = load_model("fusion.models.helix:HelixDoc", {"alpha": 0.02, "q": [0.1, 0.1, 0.1, 0.1, 0.01]})
    assert isinstance(doc, HelixDoc) and doc.alpha == 0.02


@pytest.mark.parametrize("name", ["helix3d_ekf", "helix3d_ekf_doc"])
def test_loaded_helix_model_runs_the_reference_scenario_unchanged(name: str) -> None:
    """The loaded model gives the reference run bit for bit (the scenario builds the same class)."""
    ref = reference(name, seed=1)
    path = "fusion.models.helix:" + ("HelixExact" if name == "helix3d_ekf" else "HelixDoc")
    loaded = run_reference(ref, ExtendedKalmanFilter(load_model(path, {})))  # type: ignore[arg-type]
    np.testing.assert_array_equal(loaded.x, run_reference(ref).x)


BUILT_INS = {
    "cv": ConstantVelocity(ndim=3, q=0.5),
    "ct": CoordinatedTurn(q_accel=1.0, q_turn=0.1),
    "cartesian": CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0], position=(3.0, 4.0), heading_rad=0.3),
    "radar2d": Radar2D(R=[1.0, 1e-4, 0.25], position=(50.0, -20.0), heading_rad=1.0, range_rate=True),
    "radar3d": Radar3D(R=[1.0, 1e-4, 1e-4, 0.25], position=(5.0, 6.0, 7.0), heading_rad=0.4, pitch_rad=-0.2,
                       roll_rad=0.1, range_rate=True),
}


@pytest.mark.parametrize("name", list(BUILT_INS), ids=list(BUILT_INS))
def test_built_in_models_pass_the_checks(name: str) -> None:
    assert check_model(BUILT_INS[name], name=name) is BUILT_INS[name]


class WrongJacobian(HelixExact):
    """HelixExact with d x' / d omega off by a factor of 2."""

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        J = super().jacobian(x, dt_s).copy()
        J[..., 0, 3] *= 2.0
        return J


class SlightlyWrongJacobian(HelixExact):
    """A 0.5 % error in one entry (d z' / d vz = dt): above the 1e-4 tolerance."""

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        J = super().jacobian(x, dt_s).copy()
        J[..., 2, 4] *= 1.005
        return J


class WrongShape(HelixExact):
    def Q(self, x: Array, dt_s: float | Array) -> Array:
        return np.eye(4)


class NaNOut(HelixExact):
    def f(self, x: Array, dt_s: float | Array) -> Array:
        return np.full(5, np.nan)


class LyingBroadcast(MotionModel):
    """Claims to broadcast but treats a stack as one state."""

    ndim_state = 2
    position_indices = (0,)
    broadcasts = True

    def f(self, x: Array, dt_s: float | Array) -> Array:
        return np.array([x[..., 0].sum() * 0 + x[..., 0].flat[0] + float(np.mean(dt_s)) * x[..., 1].flat[0],
                         x[..., 1].flat[0]])

    def jacobian(self, x: Array, dt_s: float | Array) -> Array:
        return np.array([[1.0, float(np.mean(dt_s))], [0.0, 1.0]])

    def Q(self, x: Array, dt_s: float | Array) -> Array:
        return np.eye(2) * float(np.mean(dt_s))


class BadRangeJacobian(Radar2D):
    """A measurement model with d range / d px negated."""

    def jacobian(self, x: Array) -> Array:
        J = super().jacobian(x).copy()
        J[..., 0, 0] *= -1.0
        return J


class NotAModel:
    def __init__(self, **kw: object) -> None:
        pass


HERE = __name__
REFUSED = {
    "wrong_jacobian": (f"{HERE}:WrongJacobian", {},
                       rf"model {HERE}:WrongJacobian: jacobian entry \[0, 3\] is .* but finite differences give "
                       r".* \(mismatch \|J - J_fd\| / max\(1, \|J_fd\|\) = 0\.\d+ > 0\.0001\)"),
    "slightly_wrong": (f"{HERE}:SlightlyWrongJacobian", {},
                       r"entry \[2, 4\] is 0\.1005 but finite differences give 0\.1 .* = 0\.0005 > 0\.0001"),
    "measurement_jacobian": (f"{HERE}:BadRangeJacobian", {"R": [1.0, 1e-4], "position": (30.0, 40.0)},
                             r"BadRangeJacobian: jacobian entry \[0, 0\]"),
    "shape": (f"{HERE}:WrongShape", {}, r"Q\(x, dt\) has shape \(4, 4\), expected \(5, 5\)"),
    "nan": (f"{HERE}:NaNOut", {}, r"f\(x, dt\) at x=.* holds NaN or inf"),
    "broadcast": (f"{HERE}:LyingBroadcast", {}, "broadcasts is True but f on a stack"),
    "not_a_model": (f"{HERE}:NotAModel", {}, "neither a MotionModel nor a MeasurementModel"),
    "bad_params": ("fusion.models.helix:HelixExact", {"q_position": 1.0}, r"HelixExact\(\*\*\{'q_position'"),
    "negative_param": ("fusion.models.helix:HelixExact", {"q_pos": -1.0}, "q_pos must be finite and >= 0"),
    "no_module": ("fusion.models.nonexistent:X", {}, "cannot import 'fusion.models.nonexistent'"),
    "no_attr": ("fusion.models.helix:Helix", {}, "has no 'Helix'"),
    "no_colon": ("fusion.models.helix.HelixExact", {}, "must look like 'package.module:Name'"),
}


@pytest.mark.parametrize("case", list(REFUSED), ids=list(REFUSED))
def test_bad_models_are_refused(case: str) -> None:
    path, params, match = REFUSED[case]
    with pytest.raises(ConfigError, match=match):
        load_model(path, params)


def test_check_states_can_be_given() -> None:
    """WrongJacobian's bad entry dt (-s x - c y) is 0 at x = y = 0: it passes at such states and
    not elsewhere. The check is only as good as its states (the default draws are all nonzero)."""
    on_axis = np.array([[0.0, 0.0, 3.0, 0.1, 0.5]])
    assert isinstance(load_model(f"{HERE}:WrongJacobian", {}, states=on_axis), WrongJacobian)
    with pytest.raises(ConfigError, match="entry"):
        load_model(f"{HERE}:WrongJacobian", {}, states=[[1.0, 2.0, 3.0, 0.1, 0.5]])


def test_measurement_model_default_position_cov_is_j_r_jt() -> None:
    """The protocol's default position_cov (finite differences) on a user's polar sensor."""

    class Polar(MeasurementModel):
        ndim_state, ndim_meas, angle_indices = 2, 2, (1,)
        R = np.diag([4.0, 1e-4])

        def h(self, x: Array) -> Array:
            return np.array([np.hypot(x[0], x[1]), np.arctan2(x[1], x[0])])

        def jacobian(self, x: Array) -> Array:
            r2 = x[0] ** 2 + x[1] ** 2
            r = np.sqrt(r2)
            return np.array([[x[0] / r, x[1] / r], [-x[1] / r2, x[0] / r2]])

        def position(self, z: Array) -> Array:
            return np.array([z[0] * np.cos(z[1]), z[0] * np.sin(z[1])])

    m = check_model(Polar(), name="Polar")
    z = np.array([100.0, 0.7])
    J = np.array([[np.cos(0.7), -100.0 * np.sin(0.7)], [np.sin(0.7), 100.0 * np.cos(0.7)]])
    np.testing.assert_allclose(m.position_cov(z, m.R), J @ m.R @ J.T, rtol=1e-7, atol=1e-9)  # type: ignore[union-attr]
