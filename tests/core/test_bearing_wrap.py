"""A target whose bearing crosses the +-pi line is tracked by the EKF and the UKF.

The target flies at 30 m/s across the ray of sensor bearing pi (the line where atan2 jumps from
+pi to -pi in the sensor frame), 1000 m from the sensor, for 20 s (crossing at t = 10 s).
Measurement noise: 10 m in range, 0.01 rad in bearing (0.5 m/s in range rate when used).
The filter starts from a prior drawn from N(truth0, P0).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fusion.core.kalman import ExtendedKalmanFilter
from fusion.core.measurement import Radar2D, wrap_angle
from fusion.core.motion import ConstantVelocity
from fusion.core.timebase import seconds_to_ns
from fusion.core.ukf import UnscentedKalmanFilter

DT = 0.1
K = 200
SIGMAS = (10.0, 0.01, 0.5)

# (sensor position, sensor heading): the crossing ray has world direction heading + pi.
GEOMETRIES = {
    "origin_heading0": ((0.0, 0.0), 0.0),  # the brief's case: (-1000, 300) -> (-1000, -300)
    "origin_heading_pi/2": ((0.0, 0.0), np.pi / 2),
    "offset_heading0": ((500.0, -200.0), 0.0),
    "offset_heading2": ((500.0, -200.0), 2.0),
    "offset_heading-3": ((-300.0, 800.0), -3.0),
}
FILTERS = ("ekf", "ukf")


def _scenario(sensor, heading, range_rate, seed):
    rng = np.random.default_rng(seed)
    motion = ConstantVelocity(ndim=2, q=0.01)
    back = heading + np.pi  # world direction of sensor bearing +-pi
    u = np.array([np.cos(back), np.sin(back)])
    perp = np.array([-np.sin(back), np.cos(back)])  # moving so that bearing goes +pi -> -pi
    cross = np.asarray(sensor) + 1000.0 * u
    start = cross - 10.0 * 30.0 * perp
    truth0 = np.array([start[0], 30.0 * perp[0], start[1], 30.0 * perp[1]])
    X = np.empty((K, 4))
    x = truth0
    L = np.linalg.cholesky(motion.Q_dt(DT))
    for k in range(K):
        x = motion.f(x, DT) + L @ rng.standard_normal(4)
        X[k] = x
    m = 3 if range_rate else 2
    sig = np.array(SIGMAS[:m])
    meas = Radar2D(R=sig**2, position=sensor, heading_rad=heading, range_rate=range_rate)
    z = meas.h(X) + rng.standard_normal((K, m)) * sig
    z[:, 1] = wrap_angle(z[:, 1])
    P0 = np.diag([100.0, 4.0, 100.0, 4.0])
    x0 = truth0 + np.linalg.cholesky(P0) @ rng.standard_normal(4)
    return motion, meas, X, z, x0, P0


@pytest.mark.parametrize("range_rate", [False, True], ids=["range_bearing", "with_range_rate"])
@pytest.mark.parametrize("kind", FILTERS, ids=list(FILTERS))
@pytest.mark.parametrize("geom", list(GEOMETRIES), ids=list(GEOMETRIES))
def test_bearing_crossing_pi(geom: str, kind: str, range_rate: bool) -> None:
    seed = 11
    sensor, heading = GEOMETRIES[geom]
    motion, meas, X, z, x0, P0 = _scenario(sensor, heading, range_rate, seed)
    # the measured bearing really jumps across +-pi during the run
    assert z[:80, 1].min() > 2.5 and z[-80:, 1].max() < -2.5, "geometry does not cross +-pi"
    filt = ExtendedKalmanFilter(motion) if kind == "ekf" else UnscentedKalmanFilter(motion)
    st = filt.initial(x0, P0, t_ns=0)
    nis, err, nees = np.empty(K), np.empty(K), np.empty(K)
    for k in range(K):
        st = filt.predict(st, seconds_to_ns((k + 1) * DT))
        up = filt.update(st, z[k], meas)
        st = up.state
        nis[k] = up.nis
        e = X[k] - st.x
        err[k] = np.hypot(e[0], e[2])
        nees[k] = e @ np.linalg.solve(st.P, e)
        assert abs(up.y[1]) < 0.1, f"{geom} {kind} seed={seed}: bearing residual {up.y[1]} at k={k}"
    msg = (
        f"{geom} {kind} range_rate={range_rate} seed={seed}: max pos err {err.max():.3g} m, "
        f"max NIS {nis.max():.3g}, NIS around crossing {nis[95:106].round(2)}, "
        f"mean NEES {nees.mean():.3g}"
    )
    m = meas.ndim_meas
    assert np.isfinite(nis).all() and np.isfinite(nees).all(), msg
    assert err.max() < 50.0, msg  # cross-range sigma is 10 m at 1000 m
    assert err[-50:].max() < 15.0, msg
    # NIS sane everywhere and in particular in the second around the crossing (t = 10 s)
    assert nis.max() < chi2.ppf(1 - 1e-4, m), msg
    assert nis[90:110].mean() < 2.0 * m, msg
    assert nees.mean() < 2.0 * 4, msg


def test_crossing_without_wrap_would_fail() -> None:
    """Sanity of the geometry: the raw bearing difference across the crossing is about 2 pi."""
    _, _meas, _X, z, _, _ = _scenario((0.0, 0.0), 0.0, False, 11)
    jumps = np.abs(np.diff(z[:, 1]))
    assert jumps.max() > 6.0
    assert np.abs(wrap_angle(np.diff(z[:, 1]))).max() < 0.1
