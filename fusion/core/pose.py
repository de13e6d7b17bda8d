r"""Sensor poses: where a sensor sits and how it is turned. The one convention of fusion:

    p_world = Rot p_sensor + t        p_sensor = Rot' (p_world - t)

with t the sensor's position in the world frame and Rot the rotation from the sensor frame to
the world frame (right-handed, z up). The sensor looks along its own x axis.
- 3-D: Rot = Rz(heading) Ry(pitch) Rx(roll), the intrinsic z-y'-x'' sequence (turn by heading
  about z, then by pitch about the new y, then by roll about the newest x); the same matrix as
  scipy's Rotation.from_euler("ZYX", [heading, pitch, roll]) and as ROS's roll-pitch-yaw.
      Rz(a) = [[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]]
      Ry(b) = [[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]]
      Rx(g) = [[1, 0, 0], [0, cg, -sg], [0, sg, cg]]
  The boresight in the world is Rot e_x = (cos h cos p, sin h cos p, -sin p): with z up, a
  positive pitch tilts the boresight DOWN (right-hand rule about y); a radar looking 5 degrees
  up has pitch_rad = -0.087.
- 2-D: Rot = [[cos h, -sin h], [sin h, cos h]] (heading only).
- 1-D: Rot = [[1]] (an offset only).
All angles are in radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_vector
from fusion.errors import ConfigError


def rotation(heading_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0) -> Array:
    """Rot = Rz(heading) Ry(pitch) Rx(roll) (3 x 3)."""
    ca, sa = math.cos(heading_rad), math.sin(heading_rad)
    cb, sb = math.cos(pitch_rad), math.sin(pitch_rad)
    cg, sg = math.cos(roll_rad), math.sin(roll_rad)
    return np.array([
        [ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
        [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
        [-sb, cb * sg, cb * cg],
    ])


def _angle(name: str, a: float) -> float:
    """A finite angle in radians (NaN would turn every later update into NaN)."""
    return float(as_vector(name, [a], 1)[0])


@dataclass(frozen=True, slots=True)
class Pose:
    """A sensor pose in d = 1, 2 or 3 dimensions: t (d,), Rot (d, d), and the angles it came from."""

    t: Array
    Rot: Array
    heading_rad: float = 0.0
    pitch_rad: float = 0.0
    roll_rad: float = 0.0

    @classmethod
    def create(
        cls, position: ArrayLike, *, heading_rad: float = 0.0, pitch_rad: float = 0.0, roll_rad: float = 0.0
    ) -> Pose:
        """A validated pose; a rotation that cannot apply in this dimension is refused (a 1-D
        pose has no angle, a 2-D pose a heading only)."""
        t = as_vector("position", position)
        d = t.shape[0]
        h, p, r = (_angle(n, a) for n, a in (("heading_rad", heading_rad), ("pitch_rad", pitch_rad),
                                            ("roll_rad", roll_rad)))
        if d == 3:
            return cls(t, rotation(h, p, r), h, p, r)
        if d == 2:
            if p or r:
                raise ConfigError(f"a 2-D pose has a heading only; got pitch_rad={p}, roll_rad={r}")
            c, s = math.cos(h), math.sin(h)
            return cls(t, np.array([[c, -s], [s, c]]), h)
        if d == 1:
            if h or p or r:
                raise ConfigError(f"a 1-D pose is an offset only; got heading {h}, pitch {p}, roll {r}")
            return cls(t, np.eye(1))
        raise ConfigError(f"a pose is 1-, 2- or 3-D, got a position of length {d}")

    @property
    def ndim(self) -> int:
        return int(self.t.shape[0])

    @property
    def is_identity(self) -> bool:
        return not self.t.any() and not (self.heading_rad or self.pitch_rad or self.roll_rad)

    def to_world(self, p: Array) -> Array:
        """Rot p + t for points p (..., d) given in the sensor frame."""
        return p @ self.Rot.T + self.t

    def to_sensor(self, p: Array) -> Array:
        """Rot' (p - t) for points p (..., d) given in the world frame."""
        return (p - self.t) @ self.Rot
