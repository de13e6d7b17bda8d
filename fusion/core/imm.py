r"""Interacting multiple model (IMM) estimator over a bank of filters sharing one state space.

Mode switching follows elapsed time, not the number of predictions: the mode is a
continuous-time Markov chain with rate matrix Lambda (see fusion.core.switching), and a step of
dt seconds switches with p_ij = Pi(dt)_ij = expm(Lambda dt)_ij, so Pi(0) = I and
Pi(a + b) = Pi(a) Pi(b).

With mode probabilities mu_i and p_ij = Pi(dt)_ij, for dt > 0:
    mixing      c_j = sum_i p_ij mu_i,   w_ij = p_ij mu_i / c_j
                x0_j = sum_i w_ij x_i,   P0_j = sum_i w_ij (P_i + (x_i - x0_j)(x_i - x0_j)')
    predict     each filter j predicts (x0_j, P0_j); predicted mode probabilities are c
    update      each filter j updates, likelihood L_j;  mu_j = c_j L_j / sum_k c_k L_k
    combine     x = sum mu_j x_j,   P = sum mu_j (P_j + (x_j - x)(x_j - x)')
At dt = 0 there is no mixing and no prediction: the state is returned unchanged.
The filters may be KF, EKF or UKF, each with its own motion model (e.g. low- and high-noise
constant velocity, or constant velocity embedded in the coordinated-turn state).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_vector
from fusion.core.gaussian import GaussianState, Update
from fusion.core.measurement import MeasurementModel
from fusion.core.switching import check_rates, transition_matrix
from fusion.core.timebase import dt_seconds
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


def combine_each(xs: Array, Ps: Array, mu: Array) -> tuple[Array, Array]:
    """`combine` of each row of a stack: xs (k, M, n), Ps (k, M, n, n), mu (k, M) -> x (k, n),
    P (k, n, n), by the same numpy operations over the stack (matmul and einsum take each row
    as combine does: the same bits, tests/tracking/test_scan_kernels.py), in a few calls instead of
    a Python call per row."""
    x = np.matmul(mu[:, None, :], xs)[:, 0]
    d = xs - x[:, None, :]
    P = np.einsum("kj,kjab->kab", mu, Ps) + np.matmul(np.swapaxes(d, -1, -2) * mu[:, None, :], d)
    return x, 0.5 * (P + np.swapaxes(P, -1, -2))


@dataclass(frozen=True, slots=True)
class IMMState:
    """Per-model states (means xs (M, n), covariances Ps (M, n, n), kept stacked so that many
    tracks stack without unpacking), mode probabilities mu, and their moment-matched
    combination (x, P)."""

    xs: Array
    Ps: Array
    mu: Array
    x: Array
    P: Array
    t_ns: int

    @classmethod
    def from_components(cls, components: Sequence[GaussianState], mu: Array) -> IMMState:
        xs = np.stack([c.x for c in components])
        Ps = np.stack([c.P for c in components])
        x, P = combine(xs, Ps, mu)
        return cls(xs, Ps, mu, x, P, components[0].t_ns)

    @property
    def components(self) -> tuple[GaussianState, ...]:
        """Each model's state."""
        return tuple(GaussianState(self.xs[j], self.Ps[j], self.t_ns) for j in range(self.xs.shape[0]))

    @property
    def ndim(self) -> int:
        return int(self.x.shape[0])

    @property
    def std(self) -> Array:
        return np.sqrt(np.diagonal(self.P))


class IMM:
    """The IMM estimator with time-based switching; `rates` is the rate matrix Lambda in 1/s
    (fusion.core.switching: `rates_from_sojourn` builds it from mean sojourn times).

    Pi(dt) is computed once per distinct dt and kept (up to CACHE_SIZE values, then the cache
    starts over): sensors at fixed rates give few distinct steps.
    """

    CACHE_SIZE = 4096

    def __init__(self, filters: Sequence[Filter], *, rates: ArrayLike) -> None:
        if len(filters) < 2:
            raise ConfigError("an IMM needs at least two filters")
        n = filters[0].ndim_state
        if any(f.ndim_state != n for f in filters):
            raise ConfigError("every filter of an IMM must share one state space")
        self.filters = tuple(filters)
        self.rates = check_rates(rates, len(filters))
        self._pi: dict[float, Array] = {}

    @property
    def ndim_state(self) -> int:
        return self.filters[0].ndim_state

    def transition(self, dt_s: float) -> Array:
        """Pi(dt) = expm(Lambda dt) for this IMM's rates (cached per dt)."""
        Pi = self._pi.get(dt_s)
        if Pi is None:
            if len(self._pi) >= self.CACHE_SIZE:
                self._pi.clear()
            Pi = self._pi[dt_s] = transition_matrix(self.rates, dt_s)
        return Pi

    def initial(self, x: ArrayLike, P: ArrayLike, *, t_ns: int, mu: ArrayLike | None = None) -> IMMState:
        st = GaussianState.create(x, P, t_ns=t_ns)
        M = len(self.filters)
        m = np.full(M, 1.0 / M) if mu is None else as_vector("mu", mu, M)
        if (m < 0).any() or abs(m.sum() - 1.0) > 1e-9:
            raise ConfigError("mu must be a probability vector")
        return IMMState.from_components([st] * M, m)

    def predict(self, state: IMMState, t_ns: int, *, u: ArrayLike | None = None) -> IMMState:
        """Mix with Pi(dt) and predict every mode to t_ns (>= state.t_ns).

        At dt = 0 nothing moves, switches or mixes: `state` itself is returned.
        """
        dt = dt_seconds(state.t_ns, t_ns)
        if dt == 0.0:
            return state
        T = self.transition(dt)
        c = state.mu @ T
        W = (T * state.mu[:, None]) / np.where(c > 0, c, 1.0)  # W[i, j] = w_ij
        xs, Ps = state.xs, state.Ps
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
