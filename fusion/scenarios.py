"""The reference scenarios of shared/scenarios.md: truth, noisy measurements and filter setup.

Pure and seeded: `reference(name, seed=...)` returns the same arrays for the same seed. Truth
noise is sampled with a Cholesky factor of Q (not the element-wise square root one source
document uses). Measurement k is taken at t_ns[k] = (k + 1) * dt; the filter starts at t = 0.

Choices where the documents are silent or contradict themselves (stated once, here):
- cv1d_d: dt = 0.1 s, 100 steps, input u = +1 m/s^2 for 3 s, 0 for 3 s, -1 m/s^2 after; the
  truth starts at rest at 0 and is driven by the same white-noise Q the filter assumes (q = 1).
- maneuver2d, radar2d, cv1d_a: truth is driven by the filter's white-noise-acceleration Q.
- helix3d (linear): state [x, y, z, vz]; x-y rotate by the known 0.1 rad per step (the
  linearisation about the circle), z climbs at vz; Q = 0.1 I, R = I, P0 = I.
- helix3d_ekf_doc: the document's nonlinear model exactly as written, fusion.models.helix.HelixDoc
  ([x, y, z, w, a], x' = x - w y dt, y' = y + w x dt, z' = z + w dt, a' = a + alpha dt). It uses
  one w both as turn rate and climb rate and R = 0.5 I against measurement noise of variance 1,
  so it cannot be consistent; it is kept to show that a user's model is expressible and tracks.
- helix3d_ekf: the consistent nonlinear version, fusion.models.helix.HelixExact: state
  [x, y, z, omega, vz] with an exact rotation by omega dt, Q = diag(0.1, 0.1, 0.1, 1e-6, 1e-4) dt,
  R = I (the true noise), P0 = I. Its truth is the model itself, driven by that Q, starting on
  the documented helix.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fusion.core.checks import Array
from fusion.core.imm import IMM, Filter
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition, MeasurementModel, Radar2D
from fusion.core.motion import ConstantVelocity, LinearModel, MotionModel
from fusion.core.switching import rates_from_sojourn
from fusion.core.timebase import seconds_to_ns
from fusion.errors import ConfigError
from fusion.models.helix import HelixDoc, HelixExact, HelixLinear

REFERENCE_NAMES: tuple[str, ...] = (
    "cv1d_a",
    "cv1d_b",
    "cv1d_c",
    "cv1d_d",
    "maneuver2d",
    "radar2d",
    "helix3d",
    "helix3d_ekf",
    "helix3d_ekf_doc",
)


@dataclass(frozen=True)
class Reference:
    """One reference scenario: truth at each measurement time, the measurements, the filter."""

    name: str
    dt_s: float
    t_ns: np.ndarray  # (K,) int64, measurement times; the filter starts at t = 0
    truth0: Array  # (n,) true state at t = 0
    truth: Array  # (K, n) true state at t_ns[k], in the filter's state layout
    z: Array  # (K, m) measurements
    motion: MotionModel
    meas: MeasurementModel
    x0: Array
    P0: Array
    layout: tuple[str, ...]  # names of the state components
    u: Array | None = None  # (K, p) control input applied on the step ending at t_ns[k]
    sensor_kind: str = "cartesian"  # or "radar"
    notes: str = ""
    extra: dict[str, object] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return int(self.t_ns.shape[0])

    def make_filter(self, *, check: bool = True) -> Filter:
        if self.motion.is_linear and self.meas.is_linear:
            return KalmanFilter(self.motion, check=check)  # type: ignore[arg-type]
        return ExtendedKalmanFilter(self.motion, check=check)


def noise_factor(Q: Array) -> Array:
    """A matrix L with L L' = Q for a symmetric positive semi-definite Q (Cholesky if PD)."""
    try:
        return np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(Q)
        return V * np.sqrt(np.clip(w, 0.0, None))


def _simulate(
    motion: MotionModel, x0: Array, dt: float, K: int, rng: np.random.Generator,
    *, noise: bool = True, u: Array | None = None,
) -> Array:
    X = np.empty((K, x0.shape[0]))
    x = x0
    for k in range(K):
        x = motion.f(x, dt)
        if u is not None:
            x = x + motion.control(dt) @ u[k]
        if noise:
            x = x + noise_factor(motion.Q(x, dt)) @ rng.standard_normal(x.shape[0])
        X[k] = x
    return X


def _times(dt: float, K: int) -> np.ndarray:
    return np.array([seconds_to_ns((k + 1) * dt) for k in range(K)], dtype=np.int64)


def _cartesian(truth: Array, meas: CartesianPosition, rng: np.random.Generator) -> Array:
    L = noise_factor(meas.R)
    return meas.h(truth) + rng.standard_normal((truth.shape[0], meas.ndim_meas)) @ L.T


def _cv1d(variant: str, rng: np.random.Generator) -> Reference:
    F1 = lambda dt: np.array([[1.0, dt], [0.0, 1.0]])  # noqa: E731
    layout = ("p", "v")
    u = None
    if variant == "a":
        dt, K, r = 0.1, 100, 0.1
        motion: MotionModel = ConstantVelocity(ndim=1, q=0.01)
        truth0 = np.array([0.0, 1.0])
        truth = _simulate(motion, truth0, dt, K, rng)
        meas = CartesianPosition(ndim_state=2, indices=(0,), R=[r**2])
        x0, P0 = np.zeros(2), np.eye(2)
    elif variant == "b":
        dt, K = 1.0, 20
        motion = LinearModel(F=F1, Q=lambda dt: 0.01 * np.eye(2), position_indices=(0,), velocity_indices=(1,))
        truth0 = np.array([0.0, 1.0])
        truth = _simulate(motion, truth0, dt, K, rng, noise=False)
        meas = CartesianPosition(ndim_state=2, indices=(0,), R=[0.1])
        x0, P0 = np.array([0.0, 1.0]), np.eye(2)
    elif variant == "c":
        dt, K = 1.0, 50
        motion = LinearModel(F=F1, Q=lambda dt: np.diag([1.0, 3.0]), position_indices=(0,), velocity_indices=(1,))
        truth0 = np.array([0.0, 0.5])
        truth = _simulate(motion, truth0, dt, K, rng, noise=False)
        meas = CartesianPosition(ndim_state=2, indices=(0,), R=[100.0])
        x0, P0 = np.zeros(2), np.eye(2)
    elif variant == "d":
        dt, K = 0.1, 100
        motion = ConstantVelocity(ndim=1, q=1.0, with_control=True)
        tk = (np.arange(K) + 1) * dt
        u = np.where(tk <= 3.0, 1.0, np.where(tk <= 6.0, 0.0, -1.0))[:, None]
        truth0 = np.zeros(2)
        truth = _simulate(motion, truth0, dt, K, rng, u=u)
        meas = CartesianPosition(ndim_state=2, indices=(0,), R=[1.0])
        x0, P0 = np.zeros(2), 1000.0 * np.eye(2)
    else:
        raise ConfigError(f"unknown cv1d variant {variant!r}")
    z = _cartesian(truth, meas, rng)  # type: ignore[arg-type]
    return Reference(f"cv1d_{variant}", dt, _times(dt, K), truth0, truth, z, motion, meas, x0, P0, layout, u)


def _maneuver2d(rng: np.random.Generator) -> Reference:
    dt, K = 0.1, 200
    motion = ConstantVelocity(ndim=2, q=0.01)
    truth0 = np.array([0.0, 1.0, 0.0, 1.0])
    a = _simulate(motion, truth0, dt, 100, rng)
    mid = a[-1].copy()
    mid[1], mid[3] = 0.5, 1.5  # the manoeuvre at t = 10 s, unknown to the filter
    b = _simulate(motion, mid, dt, 100, rng)
    truth = np.vstack([a[:-1], mid[None], b])
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.01, 0.01])
    z = _cartesian(truth, meas, rng)
    return Reference(
        "maneuver2d", dt, _times(dt, K), truth0, truth, z, motion, meas, np.zeros(4), np.eye(4),
        ("x", "vx", "y", "vy"), extra={"maneuver_t_ns": seconds_to_ns(10.0)},
    )


def _radar2d(rng: np.random.Generator) -> Reference:
    dt, K = 0.1, 200
    motion = ConstantVelocity(ndim=2, q=0.01)
    truth0 = np.array([1000.0, 20.0, 1000.0, -15.0])
    truth = _simulate(motion, truth0, dt, K, rng)
    meas = Radar2D(R=[10.0**2, 0.01**2])
    z = meas.h(truth) + rng.standard_normal((K, 2)) * np.array([10.0, 0.01])
    z[:, 1] = np.pi - np.mod(np.pi - z[:, 1], 2 * np.pi)
    return Reference(
        "radar2d", dt, _times(dt, K), truth0, truth, z, motion, meas,
        np.array([900.0, 25.0, 900.0, -10.0]), 100.0 * np.eye(4), ("x", "vx", "y", "vy"),
        sensor_kind="radar",
    )


def _helix_truth(K: int) -> Array:
    k = np.arange(K + 1)
    th = 0.1 * k
    return np.stack([-20.0 * np.sin(th), 20.0 * np.cos(th), 0.5 * k], axis=-1)  # starts at (0, 20, 0)


def _helix(version: str, rng: np.random.Generator) -> Reference:
    dt, K = 1.0, 100
    pos = _helix_truth(K)
    if version == "linear":
        motion: MotionModel = HelixLinear(turn_radps=0.1, q=0.1)  # at dt = 1 s the document's F and Q
        full = np.hstack([pos, np.full((K + 1, 1), 0.5)])
        truth0, truth = full[0], full[1:]
        meas = CartesianPosition(ndim_state=4, indices=(0, 1, 2), R=np.ones(3))
        x0, P0, layout, name = np.array([0.0, 20.0, 0.0, 0.5]), np.eye(4), ("x", "y", "z", "vz"), "helix3d"
        z = pos[1:] + rng.standard_normal((K, 3))
    elif version == "ekf":
        motion = HelixExact()
        truth0 = np.array([0.0, 20.0, 0.0, 0.1, 0.5])
        truth = _simulate(motion, truth0, dt, K, rng)
        meas = CartesianPosition(ndim_state=5, indices=(0, 1, 2), R=np.ones(3))
        z = truth[:, :3] + rng.standard_normal((K, 3))
        x0, P0, layout, name = truth0.copy(), np.eye(5), ("x", "y", "z", "omega", "vz"), "helix3d_ekf"
    else:
        motion = HelixDoc()
        truth0 = np.array([0.0, 20.0, 0.0, 0.1, 0.5])  # true turn rate and climb rate
        truth = np.hstack([pos[1:], np.tile([0.1, 0.5], (K, 1))])
        meas = CartesianPosition(ndim_state=5, indices=(0, 1, 2), R=[0.5, 0.5, 0.5])
        z = pos[1:] + rng.standard_normal((K, 3))
        x0, P0, name = np.array([0.0, 20.0, 0.0, 0.5, 0.1]), np.eye(5), "helix3d_ekf_doc"
        layout = ("x", "y", "z", "w", "a")
    return Reference(name, dt, _times(dt, K), truth0, truth, z, motion, meas, x0, P0, layout)


def reference(name: str, *, seed: int = 0) -> Reference:
    """Build reference scenario `name` (one of REFERENCE_NAMES) with a seeded generator."""
    rng = np.random.default_rng(seed)
    if name.startswith("cv1d_"):
        return _cv1d(name[5:], rng)
    builders = {
        "maneuver2d": lambda: _maneuver2d(rng),
        "radar2d": lambda: _radar2d(rng),
        "helix3d": lambda: _helix("linear", rng),
        "helix3d_ekf": lambda: _helix("ekf", rng),
        "helix3d_ekf_doc": lambda: _helix("doc", rng),
    }
    if name not in builders:
        raise ConfigError(f"unknown scenario {name!r}; known: {', '.join(REFERENCE_NAMES)}")
    return builders[name]()


@dataclass(frozen=True)
class Run:
    """The outcome of running a reference scenario's filter over its measurements."""

    x: Array  # (K, n) posterior means
    P: Array  # (K, n, n) posterior covariances
    nis: Array  # (K,)
    nees: Array  # (K,) against the truth


def run_reference(ref: Reference, filt: Filter | None = None) -> Run:
    """Predict and update once per measurement, in order, and score against the truth."""
    f = filt or ref.make_filter()
    st = f.initial(ref.x0, ref.P0, t_ns=0)  # type: ignore[attr-defined]
    K, n = ref.n_steps, ref.x0.shape[0]
    xs, Ps, nis, nees = np.empty((K, n)), np.empty((K, n, n)), np.empty(K), np.empty(K)
    for k in range(K):
        st = f.predict(st, int(ref.t_ns[k]), u=None if ref.u is None else ref.u[k])
        up = f.update(st, ref.z[k], ref.meas)
        st = up.state
        xs[k], Ps[k], nis[k] = st.x, st.P, up.nis
        e = ref.truth[k] - st.x
        nees[k] = e @ np.linalg.solve(st.P, e)
    return Run(xs, Ps, nis, nees)


def maneuver_imm(ref: Reference, *, q_low: float = 0.01, q_high: float = 1.0, sojourn_s: float = 2.0) -> IMM:
    """Two constant-velocity models, low and high process noise, for maneuver2d; each mode
    lasts sojourn_s seconds on average (2 s: about 0.95 to stay over one 0.1 s step)."""
    return IMM(
        [KalmanFilter(ConstantVelocity(ndim=2, q=q_low)), KalmanFilter(ConstantVelocity(ndim=2, q=q_high))],
        rates=rates_from_sojourn([sojourn_s, sojourn_s]),
    )
