"""Measurement models loaded by import path in the service tests (fusion.models.loader)."""

from __future__ import annotations

import math

import numpy as np

from fusion.core.measurement import MeasurementModel


class RangeBearing(MeasurementModel):
    """z = (|p - s|, atan2(p_y - s_y, p_x - s_x)) of the position p = (x[0], x[2]) of a 2-D
    constant-velocity state, from a station s; the bearing is an angle."""

    ndim_meas = 2
    angle_indices = (1,)

    def __init__(self, *, station: list[float], range_std_m: float, bearing_std_rad: float,
                 wrong_jacobian: bool = False) -> None:
        self.ndim_state = 4
        self.s = np.asarray(station, dtype=np.float64)
        self.R = np.diag([range_std_m**2, bearing_std_rad**2])
        self.wrong = wrong_jacobian

    def h(self, x: np.ndarray) -> np.ndarray:
        dx, dy = x[0] - self.s[0], x[2] - self.s[1]
        return np.array([math.hypot(dx, dy), math.atan2(dy, dx)])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        dx, dy = x[0] - self.s[0], x[2] - self.s[1]
        r2 = dx * dx + dy * dy
        r = math.sqrt(r2)
        H = np.zeros((2, 4))
        H[0, 0], H[0, 2] = dx / r, dy / r
        H[1, 0], H[1, 2] = -dy / r2, dx / r2
        if self.wrong:
            H[1, 0] = -H[1, 0]
        return H

    def position(self, z: np.ndarray) -> np.ndarray:
        return self.s + z[0] * np.array([math.cos(z[1]), math.sin(z[1])])
