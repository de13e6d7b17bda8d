"""Deliberately wrong user models, loaded by import path in tests/tracking/test_custom_models.py."""

from __future__ import annotations

import numpy as np

from fusion.core.motion import MotionModel


class WrongJacobian(MotionModel):
    """Constant velocity in 1-D whose Jacobian forgets dt: F = I instead of [[1, dt], [0, 1]]."""

    ndim_state = 2
    position_indices = (0,)
    velocity_indices = (1,)

    def f(self, x, dt_s):  # type: ignore[no-untyped-def]
        return np.stack([x[..., 0] + dt_s * x[..., 1], x[..., 1]], axis=-1)

    def jacobian(self, x, dt_s):  # type: ignore[no-untyped-def]
        return np.eye(2)

    def Q(self, x, dt_s):  # type: ignore[no-untyped-def]
        return 0.1 * np.eye(2) * dt_s


class VelocityPerAxisMissing(WrongJacobian):
    """A 1-D position with two velocity components: the coarse gate's extrapolation pairs them
    axis by axis."""

    ndim_state = 3
    position_indices = (0,)
    velocity_indices = (1, 2)
