r"""Interacting multiple model (IMM) estimator over a bank of filters sharing one state space.

With mode probabilities mu_i and Markov switching p_ij = P(model j now | model i before):
    mixing      c_j = sum_i p_ij mu_i,   w_ij = p_ij mu_i / c_j
                x0_j = sum_i w_ij x_i,   P0_j = sum_i w_ij (P_i + (x_i - x0_j)(x_i - x0_j)')
    predict     each filter j predicts (x0_j, P0_j); predicted mode probabilities are c
    update      each filter j updates, likelihood L_j;  mu_j = c_j L_j / sum_k c_k L_k
    combine     x = sum mu_j x_j,   P = sum mu_j (P_j + (x_j - x)(x_j - x)')
The filters may be KF, EKF or UKF, each with its own motion model (e.g. low- and high-noise
constant velocity, or constant velocity embedded in the coordinated-turn state).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_matrix, as_vector
from fusion.core.gaussian import GaussianState, Update
from fusion.core.measurement import MeasurementModel
from fusion.errors import ConfigError


class Filter(Protocol):
    """What the IMM (and the tracker) needs of a filter."""

    @property
    def ndim_state(self) -> int: ...

    def predict(self, state: GaussianState, t_ns: int, *, u: ArrayLike | None = None) -> GaussianState: ...

    def update(
        self, state: GaussianState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update: ...


def combine(xs: Array, Ps: Array, mu: Array) -> tuple[Array, Array]:
    """Moment-matched mixture: x = sum mu x_j, P = sum mu (P_j + dx dx')."""
    x = mu @ xs
    d = xs - x
    P = np.einsum("j,jab->ab", mu, Ps) + (d.T * mu) @ d
    return x, 0.5 * (P + P.T)


@dataclass(frozen=True, slots=True)
class IMMState:
    """Per-model states, mode probabilities mu, and their moment-matched combination (x, P)."""

    components: tuple[GaussianState, ...]
    mu: Array
    x: Array
    P: Array
    t_ns: int

    @classmethod
    def from_components(cls, components: Sequence[GaussianState], mu: Array) -> IMMState:
        xs = np.stack([c.x for c in components])
        Ps = np.stack([c.P for c in components])
        x, P = combine(xs, Ps, mu)
        return cls(tuple(components), mu, x, P, components[0].t_ns)

    @property
    def ndim(self) -> int:
        return int(self.x.shape[0])

    @property
    def std(self) -> Array:
        return np.sqrt(np.diagonal(self.P))


class IMM:
    """The IMM estimator. `transition[i, j]` is the per-prediction switching probability."""

    def __init__(self, filters: Sequence[Filter], transition: ArrayLike) -> None:
        if len(filters) < 2:
            raise ConfigError("an IMM needs at least two filters")
        n = filters[0].ndim_state
        if any(f.ndim_state != n for f in filters):
            raise ConfigError("every filter of an IMM must share one state space")
        M = len(filters)
        T = as_matrix("transition", transition, M, M)
        if (T < 0).any() or not np.allclose(T.sum(axis=1), 1.0, atol=1e-9):
            raise ConfigError("transition must be a row-stochastic matrix (rows sum to 1)")
        self.filters = tuple(filters)
        self.transition = T

    @property
    def ndim_state(self) -> int:
        return self.filters[0].ndim_state

    def initial(self, x: ArrayLike, P: ArrayLike, *, t_ns: int, mu: ArrayLike | None = None) -> IMMState:
        st = GaussianState.create(x, P, t_ns=t_ns)
        M = len(self.filters)
        m = np.full(M, 1.0 / M) if mu is None else as_vector("mu", mu, M)
        if (m < 0).any() or abs(m.sum() - 1.0) > 1e-9:
            raise ConfigError("mu must be a probability vector")
        return IMMState.from_components([st] * M, m)

    def predict(self, state: IMMState, t_ns: int, *, u: ArrayLike | None = None) -> IMMState:
        c = state.mu @ self.transition
        W = (self.transition * state.mu[:, None]) / np.where(c > 0, c, 1.0)  # W[i, j] = w_ij
        xs = np.stack([s.x for s in state.components])
        Ps = np.stack([s.P for s in state.components])
        out = []
        for j, f in enumerate(self.filters):
            x0, P0 = combine(xs, Ps, W[:, j])
            out.append(f.predict(GaussianState(x0, P0, state.t_ns), t_ns, u=u))
        return IMMState.from_components(out, c)

    def update(
        self, state: IMMState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update:
        """Update every model; y, S and NIS are of the mixture of predicted measurements."""
        ups = [f.update(s, z, model, R=R) for f, s in zip(self.filters, state.components, strict=True)]
        ll = np.array([u.log_likelihood for u in ups])
        a = np.log(np.maximum(state.mu, 1e-300)) + ll
        amax = a.max()
        mix_ll = float(amax + np.log(np.exp(a - amax).sum()))
        mu = np.exp(a - mix_ll)
        mu = mu / mu.sum()
        c = state.mu
        ys = np.stack([u.y for u in ups])
        y = c @ ys
        dy = ys - y
        S = np.einsum("j,jab->ab", c, np.stack([u.S for u in ups])) + (dy.T * c) @ dy
        nis = float(y @ np.linalg.solve(S, y))
        new = IMMState.from_components([u.state for u in ups], mu)
        return Update(new, y, S, nis, mix_ll)  # type: ignore[arg-type]
