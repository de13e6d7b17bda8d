"""Measurement models: z = h(x) + v, v ~ N(0, R).

Each model works on one state (n,) or a stack (..., n). Angles in z are wrapped into
(-pi, pi] by `residual`, and averaged on the circle by `mean` (used by the UKF). Every sensor
has a pose (fusion.core.pose: p_world = Rot p_sensor + t); z is given in the sensor's frame.

- CartesianPosition: z = Rot' (x[indices] - t) (linear; without a pose any subset of state
  components, z = x[indices]); H = Rot' S with S the selection of `indices`.
- Radar2D, Radar3D (fusion.core.radar, re-exported here): range, bearing or azimuth and
  elevation (and range rate) in the sensor's frame.

`position(z)` is the world point a measurement stands for (initiation, display) and
`position_cov(z, R)` its covariance J R J', J = d position / dz.

`kernel_kind` and `kernel_spec` name a compiled twin of h, H and the residual
(fusion.core.compiled_step, which documents the parameter layouts) that the single-state filters
use; KERNEL_NONE (every model but CartesianPosition and Radar2D, and any subclass of those that
does not set them again) means the filters call h, jacobian and residual. The parameters are
taken at construction: a model's configuration does not change afterwards.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance
from fusion.core.pose import Pose
from fusion.errors import ConfigError

TWO_PI = 2.0 * np.pi
KERNEL_NONE, KERNEL_CARTESIAN, KERNEL_RADAR2D = 0, 1, 2


def wrap_angle_scalar(a: float) -> float:
    """wrap_angle for one float: pi - ((pi - a) mod 2 pi), with the same edge at +pi."""
    r = math.pi - math.fmod(math.pi - a, TWO_PI)
    if r > math.pi:  # fmod keeps the sign of its argument; numpy's mod does not
        r -= TWO_PI
    if abs(r) > math.pi - 1e-9:  # at the +-pi edge, exactly what wrap_angle does
        return float(wrap_angle(a))
    return r


def wrap_angle(a: ArrayLike) -> Array:
    """Wrap angles into (-pi, pi]: wrap(a) = pi - ((pi - a) mod 2 pi).

    When pi - a is a tiny negative number the float mod rounds up to exactly 2 pi, giving -pi;
    that one value is mapped to +pi.
    """
    w = np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), TWO_PI)
    return np.where(w <= -np.pi, w + TWO_PI, w)


class MeasurementModel(ABC):
    """h, its Jacobian, the default noise R, angle-aware residual and mean, and the measured
    point in the world with its covariance (the protocol is written out in fusion.models.loader).

    broadcasts: h and jacobian accept a stack of states (..., n).
    """

    ndim_state: int
    ndim_meas: int
    R: Array
    is_linear: bool = False
    angle_indices: tuple[int, ...] = ()
    broadcasts: bool = False
    kernel_kind: int = KERNEL_NONE
    kernel_spec: Array | None = None

    @abstractmethod
    def h(self, x: Array) -> Array:
        """The noise-free measurement of state x."""

    @abstractmethod
    def jacobian(self, x: Array) -> Array:
        """dh/dx at x."""

    def residual(self, z: Array, zhat: Array) -> Array:
        """z - zhat with angle components wrapped into (-pi, pi]."""
        y = z - zhat
        if y.ndim == 1:  # one measurement: plain floats are ~10x cheaper than ufuncs here
            for i in self.angle_indices:
                y[i] = wrap_angle_scalar(float(y[i]))
            return y
        if len(self.angle_indices) == 1:  # one angle: a view, not a fancy index (~2 us less)
            i = self.angle_indices[0]
            y[..., i] = wrap_angle(y[..., i])
        elif self.angle_indices:
            idx = list(self.angle_indices)
            y[..., idx] = wrap_angle(y[..., idx])
        return y

    def mean(self, Z: Array, weights: Array) -> Array:
        """Weighted mean of measurement points Z (k, m); angles averaged on the circle."""
        zbar = weights @ Z
        for i in self.angle_indices:
            zbar[i] = np.arctan2(weights @ np.sin(Z[:, i]), weights @ np.cos(Z[:, i]))
        return zbar

    @abstractmethod
    def position(self, z: Array) -> Array:
        """The measured point in world Cartesian coordinates (for initiation and plots)."""

    def position_cov(self, z: Array, R: Array) -> Array:
        """Covariance of position(z) for one measurement z (m,) with noise R: J R J' with
        J = d position / dz by central differences (step 1e-6 max(1, |z_j|)); the built-in
        models override it with the analytic J."""
        zv = np.asarray(z, dtype=np.float64)
        cols = []
        for j in range(zv.shape[0]):
            e = np.zeros_like(zv)
            e[j] = 1e-6 * max(1.0, abs(float(zv[j])))
            cols.append((self.position(zv + e) - self.position(zv - e)) / (2 * e[j]))
        J = np.stack(cols, axis=-1)
        C = J @ R @ J.T
        return 0.5 * (C + C.T)


def noise_covariance(R: ArrayLike, m: int) -> Array:
    """R as a validated m x m covariance (a vector is its diagonal): a read-only array of its own,
    as a model's configuration does not change after construction (the filters keep copies)."""
    R = np.asarray(R, dtype=np.float64)
    if R.ndim == 1:
        R = np.diag(R)
    out = as_covariance("R", R, m)  # a new array (the symmetrised R), never the caller's
    out.flags.writeable = False
    return out


class CartesianPosition(MeasurementModel):
    """A position sensor: z = Rot' (x[indices] - t) in the sensor's frame, H = Rot' S.

    R is (m, m) or its diagonal. The pose (position, heading_rad, pitch_rad, roll_rad; see
    fusion.core.pose) has the measurement's dimension m = len(indices) (1, 2 or 3); without
    one, z = x[indices] for any m. position(z) = Rot z + t, position_cov(z, R) = Rot R Rot'.
    """

    is_linear = True
    broadcasts = True
    kernel_kind = KERNEL_CARTESIAN

    def __init_subclass__(cls, **kwargs: object) -> None:
        """A subclass may change h: it takes the generic path unless it sets kernel_kind again."""
        super().__init_subclass__(**kwargs)
        if "kernel_kind" not in cls.__dict__:
            cls.kernel_kind = KERNEL_NONE

    def __init__(
        self,
        *,
        ndim_state: int,
        indices: tuple[int, ...],
        R: ArrayLike,
        position: ArrayLike | None = None,
        heading_rad: float = 0.0,
        pitch_rad: float = 0.0,
        roll_rad: float = 0.0,
    ) -> None:
        if not indices or any(not 0 <= i < ndim_state for i in indices):
            raise ConfigError(f"indices {indices} must pick components of a {ndim_state}-state")
        self.ndim_state = ndim_state
        self.indices = tuple(indices)
        self.ndim_meas = m = len(indices)
        posed = position is not None or heading_rad or pitch_rad or roll_rad
        if posed and m > 3:
            raise ConfigError(f"a pose applies to a 1-, 2- or 3-D position, not to {m} measured components")
        self.pose: Pose | None = Pose.create(
            np.zeros(m) if position is None else position, heading_rad=heading_rad, pitch_rad=pitch_rad,
            roll_rad=roll_rad) if posed else None
        if self.pose is not None and self.pose.ndim != m:
            raise ConfigError(f"the sensor position has {self.pose.ndim} components, the measurement {m}")
        if self.pose is not None and self.pose.is_identity:
            self.pose = None
        S = np.zeros((m, ndim_state))
        S[np.arange(m), list(indices)] = 1.0
        self.H = S if self.pose is None else self.pose.Rot.T @ S
        self.R = noise_covariance(R, m)
        self._idx = np.array(indices)
        rot, t = (np.eye(m), np.zeros(m)) if self.pose is None else (self.pose.Rot, self.pose.t)
        self.kernel_spec = np.concatenate(
            [[ndim_state, self.pose is not None], self._idx, t, rot.ravel()]).astype(np.float64)
        self.kernel_spec.flags.writeable = False

    def h(self, x: Array) -> Array:
        p = x[self._idx] if x.ndim == 1 else x[..., self._idx]
        return p if self.pose is None else self.pose.to_sensor(p)

    def jacobian(self, x: Array) -> Array:
        return self.H if x.ndim == 1 else np.broadcast_to(self.H, x.shape[:-1] + self.H.shape)

    def residual(self, z: Array, zhat: Array) -> Array:
        return z - zhat

    def position(self, z: Array) -> Array:
        zv = np.asarray(z, dtype=np.float64)
        return zv if self.pose is None else self.pose.to_world(zv)

    def position_cov(self, z: Array, R: Array) -> Array:
        if self.pose is None:
            return np.asarray(R, dtype=np.float64)
        C = self.pose.Rot @ R @ self.pose.Rot.T
        return 0.5 * (C + C.T)


def __getattr__(name: str) -> type[MeasurementModel]:
    """Radar2D and Radar3D live in fusion.core.radar (which imports this module); they are
    served from here too, on first use, so that every measurement model imports from here."""
    if name in ("Radar2D", "Radar3D"):
        from fusion.core import radar

        return getattr(radar, name)  # type: ignore[no-any-return]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
