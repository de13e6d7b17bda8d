"""Sensor poses (issue #12 item 3): Cartesian sensors and radars measure in their own frame,
p_world = Rot p_sensor + t with Rot = Rz(heading) Ry(pitch) Rx(roll)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fusion.core.kalman import KalmanFilter
from fusion.core.measurement import CartesianPosition, MeasurementModel, Radar2D, Radar3D
from fusion.core.motion import ConstantVelocity
from fusion.core.pose import Pose, rotation
from fusion.errors import ConfigError, NonFiniteError


def test_cartesian_sensor_with_heading_gives_the_world_point() -> None:
    """The issue's case: a sensor at (100, 0) with heading 1 rad measuring z = (10, 0)."""
    m = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0], position=(100.0, 0.0), heading_rad=1.0)
    want = np.array([100.0 + 10.0 * math.cos(1.0), 10.0 * math.sin(1.0)])
    np.testing.assert_allclose(m.position(np.array([10.0, 0.0])), want, rtol=1e-15)
    x = np.array([want[0], 3.0, want[1], -2.0])
    np.testing.assert_allclose(m.h(x), [10.0, 0.0], atol=1e-13)
    # a track updated with that measurement lands on the world point, not at (10, 0)
    kf = KalmanFilter(ConstantVelocity(ndim=2, q=1.0))
    st = kf.initial(np.array([110.0, 0.0, 5.0, 0.0]), np.diag([1e6, 1.0, 1e6, 1.0]), t_ns=0)
    post = kf.update(st, [10.0, 0.0], m).state
    np.testing.assert_allclose(post.x[[0, 2]], want, atol=1e-4)
    # covariance of the world point: Rot R Rot'
    R = np.diag([4.0, 1.0])
    Rot = np.array([[math.cos(1.0), -math.sin(1.0)], [math.sin(1.0), math.cos(1.0)]])
    np.testing.assert_allclose(m.position_cov(np.array([10.0, 0.0]), R), Rot @ R @ Rot.T, rtol=1e-14)


def test_rotation_is_intrinsic_zyx() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        h, p, r = rng.uniform(-math.pi, math.pi, 3)
        want = Rotation.from_euler("ZYX", [h, p, r]).as_matrix()
        np.testing.assert_allclose(rotation(h, p, r), want, atol=1e-15, err_msg="seed=3")
    # positive pitch tilts the boresight (the sensor's x axis) down, z up
    assert (rotation(0.0, 0.1) @ [1.0, 0.0, 0.0])[2] < 0


POSE_REFUSED = {
    "pitch_in_2d": (lambda: Pose.create([0.0, 0.0], pitch_rad=0.1), ConfigError, "heading only"),
    "heading_in_1d": (lambda: Pose.create([0.0], heading_rad=0.1), ConfigError, "offset only"),
    "4d": (lambda: Pose.create([0.0] * 4), ConfigError, "1-, 2- or 3-D"),
    "roll_nan": (lambda: Pose.create([0.0] * 3, roll_rad=math.nan), NonFiniteError, "roll_rad"),
    "cartesian_pose_size": (lambda: CartesianPosition(ndim_state=6, indices=(0, 2, 4), R=[1.0] * 3,
                                                      position=(1.0, 2.0)), ConfigError, "3"),
    "cartesian_2d_pitch": (lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0] * 2,
                                                     pitch_rad=0.2), ConfigError, "heading only"),
    "cartesian_4_components": (lambda: CartesianPosition(ndim_state=4, indices=(0, 1, 2, 3), R=[1.0] * 4,
                                                         heading_rad=0.2), ConfigError, "not to 4"),
}


@pytest.mark.parametrize("case", list(POSE_REFUSED), ids=list(POSE_REFUSED))
def test_pose_that_cannot_apply_is_refused(case: str) -> None:
    make, err, match = POSE_REFUSED[case]
    with pytest.raises(err, match=match):
        make()


def test_radar3d_with_pitch_and_roll_hand_computed() -> None:
    """Heading 90 deg, pitch -30 deg (boresight 30 deg up), roll 90 deg. By hand:
    boresight Rot e_x = (cos90 cos30, sin90 cos30, sin30) = (0, 0.866, 0.5); the sensor's y axis
    Rot e_y = Rz(90) Ry(-30) e_z = Rz(90) (-0.5, 0, 0.866) = (0, -0.5, 0.866). A target 100 m
    along the boresight and 20 m along the sensor's y axis is at sensor-frame (100, 20, 0):
    range sqrt(10400), azimuth atan2(20, 100), elevation 0."""
    t = np.array([10.0, 20.0, 5.0])
    c30, s30 = math.cos(math.pi / 6), 0.5
    bore, yax = np.array([0.0, c30, s30]), np.array([0.0, -s30, c30])
    m = Radar3D(R=[1.0, 1e-4, 1e-4, 0.25], position=t, heading_rad=math.pi / 2, pitch_rad=-math.pi / 6,
                roll_rad=math.pi / 2, range_rate=True)
    p = t + 100.0 * bore + 20.0 * yax
    v = np.array([3.0, -4.0, 12.0])
    x = np.array([p[0], v[0], p[1], v[1], p[2], v[2]])
    d = p - t
    want = [math.sqrt(10400.0), math.atan2(20.0, 100.0), 0.0, d @ v / np.linalg.norm(d)]
    np.testing.assert_allclose(m.h(x), want, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(m.position(np.array(want)), p, rtol=1e-13)
    # roll 90 deg alone: the sensor's z axis points along world -y, its y axis along world +z
    m2 = Radar3D(R=[1.0, 1e-4, 1e-4], roll_rad=math.pi / 2)
    np.testing.assert_allclose(m2.h(np.array([0.0, 0, 0.0, 0, 50.0, 0])), [50.0, math.pi / 2, 0.0], atol=1e-13)
    # world (30, 40, 0) is sensor-frame (30, 0, -40)
    np.testing.assert_allclose(m2.h(np.array([30.0, 0, 40.0, 0, 0.0, 0])), [50.0, 0.0, math.atan2(-40.0, 30.0)],
                               atol=1e-13)


def _fd(fun, x: np.ndarray) -> np.ndarray:
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = 1e-6 * max(1.0, abs(x[j]))
        cols.append((fun(x + e) - fun(x - e)) / (2 * e[j]))
    return np.stack(cols, axis=-1)


def _check(m: MeasurementModel, x: np.ndarray, msg: str) -> None:
    z0 = m.h(x)
    Jfd = _fd(lambda s: m.residual(m.h(s), z0), x)
    err = np.abs(m.jacobian(x) - Jfd) / np.maximum(1.0, np.abs(Jfd))
    assert err.max() < 1e-6, f"{msg}: jacobian error {err.max():.3g}"
    # position inverts h, and the analytic position_cov equals the finite-difference J R J'
    pos = list(m.pos_idx) if hasattr(m, "pos_idx") else list(m.indices)
    np.testing.assert_allclose(m.position(z0), x[pos], rtol=1e-10, atol=1e-8, err_msg=msg)
    C, Cfd = m.position_cov(z0, m.R), MeasurementModel.position_cov(m, z0, m.R)
    np.testing.assert_allclose(C, Cfd, rtol=1e-6, atol=1e-9 * np.abs(Cfd).max(), err_msg=msg)


SEEDS = tuple(range(8))


@pytest.mark.parametrize("seed", SEEDS, ids=[f"seed{s}" for s in SEEDS])
def test_jacobians_and_position_cov_for_random_poses(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, p, r = rng.uniform(-math.pi, math.pi), rng.uniform(-1.4, 1.4), rng.uniform(-math.pi, math.pi)
    t3, t2 = rng.uniform(-500, 500, 3), rng.uniform(-500, 500, 2)
    x6 = np.array([*rng.uniform(-1000, 1000, 1), 5.0, *rng.uniform(-1000, 1000, 1), -7.0, 300.0, 2.0])
    x4 = x6[:4]
    msg = f"seed={seed} heading={h:.3f} pitch={p:.3f} roll={r:.3f}"
    for rr in (False, True):
        R3 = [4.0, 1e-4, 2e-4] + ([0.25] if rr else [])
        _check(Radar3D(R=R3, position=t3, heading_rad=h, pitch_rad=p, roll_rad=r, range_rate=rr), x6,
               f"Radar3D rr={rr} {msg}")
        R2 = [4.0, 1e-4] + ([0.25] if rr else [])
        _check(Radar2D(R=R2, position=t2, heading_rad=h, range_rate=rr), x4, f"Radar2D rr={rr} {msg}")
    _check(CartesianPosition(ndim_state=6, indices=(0, 2, 4), R=[1.0, 2.0, 3.0], position=t3, heading_rad=h,
                             pitch_rad=p, roll_rad=r), x6, f"Cartesian 3-D {msg}")
    _check(CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 2.0], position=t2, heading_rad=h), x4,
           f"Cartesian 2-D {msg}")
    # batched h and jacobian equal the per-state ones (the tracker gates stacks)
    m = Radar3D(R=[4.0, 1e-4, 2e-4, 0.25], position=t3, heading_rad=h, pitch_rad=p, roll_rad=r, range_rate=True)
    X = np.stack([x6, x6 + 10.0, x6 - 30.0])
    np.testing.assert_allclose(m.h(X)[2], m.h(X[2]), rtol=1e-13, atol=1e-13, err_msg=msg)
    np.testing.assert_allclose(m.jacobian(X)[1], m.jacobian(X[1]), rtol=1e-13, atol=1e-13, err_msg=msg)


def test_radar3d_yaw_only_matches_heading_offset() -> None:
    """Pitch = roll = 0: azimuth = wrap(atan2(dy, dx) - heading), elevation in the world frame."""
    m = Radar3D(R=[1.0, 1e-4, 1e-4], position=(5.0, -3.0, 2.0), heading_rad=2.5)
    x = np.array([-400.0, 0, 250.0, 0, 80.0, 0])
    dx, dy, dz = -405.0, 253.0, 78.0
    az = math.atan2(dy, dx) - 2.5
    np.testing.assert_allclose(m.h(x), [math.sqrt(dx * dx + dy * dy + dz * dz), az, math.atan2(dz, math.hypot(dx, dy))],
                               rtol=1e-14)
