"""Ground truth of the streamed scenarios: pure and seeded.

A Truth holds, per target, the true state at the sample times t_ns (K,), in a layout of named
components with positions first named x, y, z and velocities vx, vy, vz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion.core.motion import ConstantVelocity, CoordinatedTurn
from fusion.core.timebase import seconds_to_ns
from fusion.scenarios import Reference, noise_factor, reference


@dataclass(frozen=True)
class TargetTruth:
    target_id: str
    t_ns: np.ndarray  # (K,) int64
    states: np.ndarray  # (K, n)
    layout: tuple[str, ...]

    def positions(self) -> np.ndarray:
        idx = [self.layout.index(a) for a in ("x", "y", "z") if a in self.layout]
        return self.states[:, idx]


MIX_Q = 0.05  # the mix's white-noise acceleration: spectral density MIX_Q^2 = 0.0025 m^2/s^3
MIX_TURN_RADPS = 0.1  # the turning target's rate, for MIX_TURN_S seconds
MIX_TURN_S = 10.5  # ~60 degrees


def mix_truth(*, n_targets: int, dt_s: float, duration_s: float, seed: int) -> list[TargetTruth]:
    """2-D nearly-constant-velocity targets (white-noise acceleration of density MIX_Q^2): the
    first two cross each other half-way, the third flies a coordinated turn at MIX_TURN_RADPS for
    MIX_TURN_S seconds from a third of the way in, the rest start on a ring 1-3 km out, heading
    inwards. The state is [x, vx, y, vy, omega] with omega the true turn rate."""
    rng = np.random.default_rng(seed)
    K = round(duration_s / dt_s)
    model = ConstantVelocity(ndim=2, q=MIX_Q)
    L = noise_factor(model.Q_dt(dt_s))
    F = model.F(dt_s)
    turn = CoordinatedTurn(q_accel=MIX_Q, q_turn=0.0)
    turning = range(K // 3, K // 3 + round(MIX_TURN_S / dt_s))
    T = duration_s
    starts = []
    for i in range(n_targets):
        if i == 0:
            x = [-15.0 * T / 2, 15.0, -8.0 * T / 2, 8.0]
        elif i == 1:
            x = [15.0 * T / 2, -15.0, -8.0 * T / 2, 8.0]
        else:
            a = rng.uniform(0, 2 * np.pi)
            r = rng.uniform(1000.0, 3000.0)
            speed = rng.uniform(5.0, 25.0)
            h = a + np.pi + rng.uniform(-0.5, 0.5)
            x = [r * np.cos(a), speed * np.cos(h), r * np.sin(a), speed * np.sin(h)]
        starts.append(np.array(x, dtype=np.float64))
    out = []
    for i, x in enumerate(starts):
        X = np.empty((K, 5))
        for k in range(K):
            w = MIX_TURN_RADPS if i == 2 and k in turning else 0.0
            x = (turn.f(np.append(x, w), dt_s)[:4] if w else F @ x) + L @ rng.standard_normal(4)
            X[k] = np.append(x, w)
        t = np.array([seconds_to_ns((k + 1) * dt_s) for k in range(K)], dtype=np.int64)
        out.append(TargetTruth(f"target{i}", t, X, ("x", "vx", "y", "vy", "omega")))
    return out


_LAYOUTS = {"p": "x", "v": "vx"}


def reference_truth(ref: Reference) -> TargetTruth:
    """The reference scenario's truth with standard component names (and velocities for the
    helix, which the tracker's constant-velocity layout needs for scoring)."""
    names = tuple(_LAYOUTS.get(n, n) for n in ref.layout)
    X = ref.truth
    if ref.name.startswith("helix3d"):
        # x-y rotate at omega (0.1 rad/s in the documented truth): vx = -omega y, vy = omega x;
        # the reference's own components (omega; the document's w and a) are kept too, so a
        # tracker in the reference's state space is scored as well as a constant-velocity one
        omega = X[:, 3] if ref.name == "helix3d_ekf" else np.full(len(X), 0.1)
        vz = X[:, 4] if ref.name == "helix3d_ekf" else np.full(len(X), 0.5)
        cv = np.column_stack([X[:, 0], -omega * X[:, 1], X[:, 1], omega * X[:, 0], X[:, 2], vz])
        extra = [i for i, n in enumerate(ref.layout) if n not in ("x", "y", "z", "vz")]
        X = np.column_stack([cv, X[:, extra]])
        names = ("x", "vx", "y", "vy", "z", "vz", *(ref.layout[i] for i in extra))
    return TargetTruth("target0", ref.t_ns.astype(np.int64), X, names)


def load_reference(name: str, *, seed: int) -> tuple[Reference, TargetTruth]:
    ref = reference(name, seed=seed)
    return ref, reference_truth(ref)
