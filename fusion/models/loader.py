r"""Load a user's motion or measurement model by import path, and check it before any use.

The protocol is the one the built-in models follow: subclass fusion.core.motion.MotionModel or
fusion.core.measurement.MeasurementModel (their defaults fill in the optional parts).

Motion model, x' = f(x, dt) + w with w ~ N(0, Q(x, dt)):
    ndim_state: int                      n, the state dimension
    position_indices: tuple[int, ...]    state components of the position (for initiation, display)
    velocity_indices: tuple[int, ...]    of the velocity, if any (default ())
    is_linear: bool                      True only if f(x, dt) = F(dt) x (default False)
    broadcasts: bool                     True if f, jacobian and Q accept a stack (..., n) with dt
                                         of the stack's leading shape (default False)
    f(x, dt_s) -> (n,)                   the noise-free transition; dt_s in seconds, >= 0
    jacobian(x, dt_s) -> (n, n)          df/dx at the prior state x
    Q(x, dt_s) -> (n, n)                 process-noise covariance, symmetric positive semi-definite
    control(dt_s) -> (n, p) | None       B(dt) of x' = f(x, dt) + B u (optional; default None)
Measurement model, z = h(x) + v with v ~ N(0, R):
    ndim_state, ndim_meas: int           n and m
    R: (m, m)                            default noise covariance, positive definite
    is_linear: bool                      True only if h is affine in x (default False)
    angle_indices: tuple[int, ...]       components of z that are angles (default ())
    h(x) -> (m,)                         the noise-free measurement
    jacobian(x) -> (m, n)                dh/dx at x
    position(z) -> (d,)                  the world point a measurement stands for
    residual(z, zhat), mean(Z, w), position_cov(z, R)   optional (defaults: angle-aware)

`load_model("package.module:Name", params)` imports the module, builds Name(**params) and
refuses, with a ConfigError naming the path, anything that is not such a model or that fails
these checks at a few states (`states`, default: three seeded draws x = 10 N(0, I)) and steps
(`dts_s`, default 0.1 s and 1 s):
- shapes as above, every output finite, Q symmetric PSD, R symmetric PD, indices in range;
- the Jacobian against central finite differences J~_ij = (g(x + h_j e_j) - g(x - h_j e_j)) /
  (2 h_j), h_j = 1e-6 max(1, |x_j|), g = f(., dt) or residual(h(.), h(x)) (angles wrapped):
  refused when |J_ij - J~_ij| > rtol max(1, |J~_ij|) for any entry, rtol = 1e-4 by default.
  Truncation (O(h^2)) and rounding (O(eps |g| / h), ~1e-10 |g|) errors sit far below it for
  smooth models at these scales, while a wrong entry is off by O(1);
- if broadcasts: a stack evaluated at once equals the states evaluated one by one (to 1e-12).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from fusion.core.checks import Array, as_covariance
from fusion.core.measurement import MeasurementModel
from fusion.core.motion import MotionModel
from fusion.errors import ConfigError, InputError

Model = MotionModel | MeasurementModel
RTOL = 1e-4


def load_model(
    path: str,
    params: Mapping[str, object] | None = None,
    *,
    states: ArrayLike | None = None,
    dts_s: Sequence[float] = (0.1, 1.0),
    rtol: float = RTOL,
) -> Model:
    """Import "package.module:Name", build Name(**params) and `check_model` it."""
    mod_name, sep, attr = path.partition(":")
    if not sep or not mod_name or not attr:
        raise ConfigError(f"model path {path!r} must look like 'package.module:Name'")
    try:
        module = importlib.import_module(mod_name)
    except ImportError as e:
        raise ConfigError(f"model {path}: cannot import {mod_name!r}: {e}") from e
    cls = getattr(module, attr, None)
    if cls is None:
        raise ConfigError(f"model {path}: module {mod_name!r} has no {attr!r}")
    try:
        model = cls(**dict(params or {}))
    except (TypeError, ValueError) as e:
        raise ConfigError(f"model {path}: {attr}(**{dict(params or {})!r}) failed: {e}") from e
    return check_model(model, name=path, states=states, dts_s=dts_s, rtol=rtol)


def check_model(
    model: object,
    *,
    name: str,
    states: ArrayLike | None = None,
    dts_s: Sequence[float] = (0.1, 1.0),
    rtol: float = RTOL,
) -> Model:
    """The checks of `load_model` on an instance; returns it, or raises ConfigError."""
    if not isinstance(model, MotionModel | MeasurementModel):
        raise ConfigError(f"model {name}: {type(model).__name__} is neither a MotionModel nor a "
                          "MeasurementModel (subclass one of fusion.core.motion.MotionModel, "
                          "fusion.core.measurement.MeasurementModel)")
    n = getattr(model, "ndim_state", None)
    if not isinstance(n, int) or n < 1:
        raise ConfigError(f"model {name}: ndim_state must be a positive int, got {n!r}")
    if states is None:
        X = 10.0 * np.random.default_rng(0).standard_normal((3, n))
    else:
        X = np.atleast_2d(np.asarray(states, dtype=np.float64))
        if X.shape[-1] != n:
            raise ConfigError(f"model {name}: check states must have {n} components, got {X.shape}")
    try:
        if isinstance(model, MotionModel):
            _check_motion(model, name, X, dts_s, rtol)
        else:
            _check_measurement(model, name, X, rtol)
    except InputError as e:  # a shape, NaN or definiteness problem found by fusion.core.checks
        raise ConfigError(f"model {name}: {e}") from e
    return model


def _out(name: str, what: str, v: object, shape: tuple[int, ...]) -> Array:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != shape:
        raise ConfigError(f"model {name}: {what} has shape {a.shape}, expected {shape}")
    if not np.isfinite(a).all():
        raise ConfigError(f"model {name}: {what} holds NaN or inf")
    return a


def _indices(name: str, what: str, idx: object, n: int, *, empty: bool) -> None:
    if not isinstance(idx, tuple) or not all(isinstance(i, int) and 0 <= i < n for i in idx) or (
            not empty and not idx):
        raise ConfigError(f"model {name}: {what} must be a tuple of state indices in [0, {n}), got {idx!r}")


def _fd(g: Callable[[Array], Array], x: Array) -> Array:
    cols = []
    for j in range(x.shape[0]):
        e = np.zeros_like(x)
        e[j] = 1e-6 * max(1.0, abs(float(x[j])))
        cols.append((np.asarray(g(x + e), dtype=np.float64) - np.asarray(g(x - e), dtype=np.float64)) / (2 * e[j]))
    return np.stack(cols, axis=-1)


def _compare(name: str, what: str, J: Array, Jfd: Array, rtol: float, where: str) -> None:
    err = np.abs(J - Jfd) / np.maximum(1.0, np.abs(Jfd))
    i = np.unravel_index(int(np.argmax(err)), err.shape)
    if err[i] > rtol:
        raise ConfigError(
            f"model {name}: {what} entry [{i[0]}, {i[1]}] is {J[i]:.6g} but finite differences give "
            f"{Jfd[i]:.6g} (mismatch |J - J_fd| / max(1, |J_fd|) = {err[i]:.3g} > {rtol:g}) at {where}; "
            "is the Jacobian right?")


def _check_motion(m: MotionModel, name: str, X: Array, dts_s: Sequence[float], rtol: float) -> None:
    n = m.ndim_state
    _indices(name, "position_indices", m.position_indices, n, empty=False)
    _indices(name, "velocity_indices", m.velocity_indices, n, empty=True)
    if m.velocity_indices and len(m.velocity_indices) != len(m.position_indices):
        raise ConfigError(f"model {name}: velocity_indices {m.velocity_indices!r} must name one velocity per "
                          f"position axis (position_indices {m.position_indices!r}), or none")
    for dt in (float(d) for d in dts_s):
        for x in X:
            where = f"x={np.array2string(x, precision=4)}, dt={dt:g} s"
            _out(name, f"f(x, dt) at {where}", m.f(x, dt), (n,))
            J = _out(name, f"jacobian(x, dt) at {where}", m.jacobian(x, dt), (n, n))
            as_covariance(f"Q(x, dt) at {where}", _out(name, "Q(x, dt)", m.Q(x, dt), (n, n)), n, psd=True)
            _compare(name, "jacobian", J, _fd(lambda s, dt=dt: m.f(s, dt), x), rtol, where)
        B = m.control(dt)
        if B is not None and (np.ndim(B) != 2 or np.shape(B)[0] != n or not np.isfinite(B).all()):
            raise ConfigError(f"model {name}: control(dt) must be None or a finite ({n}, p) matrix")
        if m.broadcasts:
            dts = np.full(X.shape[0], dt)
            for what, stacked, one in (("f", m.f(X, dts), m.f), ("jacobian", m.jacobian(X, dts), m.jacobian),
                                       ("Q", m.Q(X, dts), m.Q)):
                rows = np.stack([np.asarray(one(x, dt), dtype=np.float64) for x in X])
                if np.shape(stacked) != rows.shape or not np.allclose(stacked, rows, rtol=1e-12, atol=1e-12):
                    raise ConfigError(f"model {name}: broadcasts is True but {what} on a stack of states "
                                      f"differs from {what} state by state (dt={dt:g} s)")


def _check_measurement(m: MeasurementModel, name: str, X: Array, rtol: float) -> None:
    n = m.ndim_state
    mdim = getattr(m, "ndim_meas", None)
    if not isinstance(mdim, int) or mdim < 1:
        raise ConfigError(f"model {name}: ndim_meas must be a positive int, got {mdim!r}")
    as_covariance("R", m.R, mdim)
    if any(not 0 <= i < mdim for i in m.angle_indices):
        raise ConfigError(f"model {name}: angle_indices {m.angle_indices} must be in [0, {mdim})")
    for x in X:
        where = f"x={np.array2string(x, precision=4)}"
        z = _out(name, f"h(x) at {where}", m.h(x), (mdim,))
        J = _out(name, f"jacobian(x) at {where}", m.jacobian(x), (mdim, n))
        _compare(name, "jacobian", J, _fd(lambda s, z=z: m.residual(np.asarray(m.h(s), dtype=np.float64), z),
                                         x), rtol, where)
        p = np.asarray(m.position(z), dtype=np.float64)
        if p.ndim != 1 or not np.isfinite(p).all():
            raise ConfigError(f"model {name}: position(h(x)) at {where} must be a finite vector, got {p!r}")
        C = _out(name, f"position_cov(h(x), R) at {where}", m.position_cov(z, m.R), (p.shape[0],) * 2)
        as_covariance(f"position_cov(h(x), R) at {where}", C, p.shape[0], psd=True)
