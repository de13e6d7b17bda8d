r"""Kalman and extended Kalman filters.

Predict (motion Jacobian F evaluated at the prior state x):
    x- = f(x, dt) (+ B u)            P- = F P F' + Q
Update with z ~ N(h(x), R), H = dh/dx at x-:
    y = z - h(x-) (angles wrapped)   S = H P- H' + R = L L'   (Cholesky; never inverted)
    K = P- H' S^-1  (two triangular solves with L)
    x+ = x- + K y                    P+ = (I - K H) P- (I - K H)' + K R K'   (Joseph form)
    NIS = y' S^-1 y = |L^-1 y|^2     log-likelihood = -(NIS + log det S + m log 2 pi) / 2

`KalmanFilter` and `ExtendedKalmanFilter` step one state with the compiled kernels of
fusion.core.compiled, which evaluate the Joseph form expanded, P - K H P - (K H P)' + K S K'
(algebraically the same as above); the tracker's batched gate loops the same kernels over a
stack (fusion.core.compiled_stack). A linear motion model predicts in one compiled call with
F(dt), Q(dt) cached per dt (fusion.core.transitions); CartesianPosition and Radar2D update in
one compiled call that also evaluates h, H, the wrapped residual and the checks of z and of a
given R (fusion.core.compiled_step). Both calls go through fusion.core.single: C where the
extension was built (the same bits as the numba kernels, without their per-argument dispatch),
numba's twins otherwise. What a call refuses goes the numpy way (h, jacobian, residual,
fusion.core.checks), which raises the typed error, so errors and messages are those of the numpy
path; results agree with it to rounding (tests/core/test_step_kernels.py).
`step(state, t_ns, z, model)` is predict then update in one compiled call: with the model's R,
fusion.core.single.step on the plan the filter keeps for that model (fusion.core.step_plan: F,
Q, the model's parameters and R packed once per time step; numba's twin is
fusion.core.compiled_packed.step_packed), with a given R fusion.core.compiled_step.step_model.
Either gives the same Update bit for bit as predict then update and the same errors
(tests/core/test_filter_step.py, tests/core/test_packed_step.py). The compiled calls keep their
intermediates in scratch (no allocation in the kernels); every array returned is fresh (its own
memory, shared with no input, no other result and nothing the filter keeps).
The plain numpy reference of the equations (predict_arrays, update_arrays) and the checked
compiled update of one state (update_single) are in fusion.core.kalman_reference, re-exported.
"""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from fusion.core import compiled as _compiled
from fusion.core import compiled_step as _step
from fusion.core.checks import Array, as_covariance, as_vector
from fusion.core.gaussian import GaussianState, Update
from fusion.core.kalman_reference import LOG_2PI, predict_arrays, update_arrays, update_single
from fusion.core.measurement import MeasurementModel
from fusion.core.motion import LinearMotionModel, MotionModel
from fusion.core.single import NOT_TAKEN as _NOT_TAKEN
from fusion.core.single import FilterCalls as _FilterCalls
from fusion.core.single import predict as _predict
from fusion.core.single import predict_numba as _predict_numba
from fusion.core.single import step as _step_call
from fusion.core.single import step_numba as _step_numba
from fusion.core.single import update as _update
from fusion.core.single import update_numba as _update_numba
from fusion.core.step_plan import StepPlan
from fusion.core.step_plan import blob as _blob
from fusion.core.step_plan import make_plan as _make_plan
from fusion.core.timebase import NS_PER_S, dt_seconds
from fusion.core.transitions import TransitionCache
from fusion.errors import ConfigError, NumericalError, ShapeError

__all__ = ["LOG_2PI", "ExtendedKalmanFilter", "FilterBase", "KalmanFilter", "predict_arrays", "update_arrays",
           "update_single"]

_F64 = np.dtype(np.float64)
_empty = np.empty
_ndarray = np.ndarray
_step_model = _step.step_model
_CHECK_Z, _CHECK_R = _step.CHECK_Z, _step.CHECK_R
_new = tuple.__new__  # GaussianState and Update are named tuples: built without their __new__


class FilterBase:
    """What every single-state filter shares: its motion model, input checks, initial state.

    Stateless: predict and update take a GaussianState and return new objects. With
    check=True (the default) inputs are validated: shapes, finiteness, R positive definite.
    The motion model is fixed at construction (`motion` is read-only).
    """

    def __init__(self, motion: MotionModel, *, check: bool = True) -> None:
        self._motion = motion
        self.check = check

    @property
    def motion(self) -> MotionModel:
        return self._motion

    @property
    def ndim_state(self) -> int:
        return self._motion.ndim_state

    def initial(self, x: ArrayLike, P: ArrayLike, *, t_ns: int) -> GaussianState:
        """A validated initial state for this filter."""
        st = GaussianState.create(x, P, t_ns=t_ns)
        if st.ndim != self.ndim_state:
            raise ShapeError(f"initial x has {st.ndim} components, the model has {self.ndim_state}")
        return st

    def _measurement(self, z: ArrayLike, R: ArrayLike | None, model: MeasurementModel) -> tuple[Array, Array]:
        """z and R as arrays (R defaults to the model's), validated when check is on."""
        if self.check:
            return as_vector("z", z, model.ndim_meas), (
                model.R if R is None else as_covariance("R", R, model.ndim_meas))
        zv = z if isinstance(z, np.ndarray) else np.asarray(z, dtype=np.float64)
        return zv, model.R if R is None else np.asarray(R, dtype=np.float64)

    def _control(self, x: Array, dt: float, u: ArrayLike | None) -> Array:
        """x + B(dt) u, refused for a model that takes no input."""
        if u is None:
            return x
        B = self._motion.control(dt)
        if B is None:
            raise ConfigError(f"{type(self._motion).__name__} takes no control input")
        return x + B @ as_vector("u", u, B.shape[1])

    def _finite(self, x: Array) -> None:
        if self.check and not np.isfinite(x).all():
            raise NumericalError(f"prediction produced a non-finite state: {x}")


class ExtendedKalmanFilter(FilterBase, _FilterCalls):
    """EKF over any motion model and any measurement model (exact KF when both are linear).

    Fast paths (the module docstring): one compiled call per predict, update or step where the
    models have compiled twins; anything else, or anything a call refuses, takes the numpy path,
    which raises the typed error. predict, update and step are fusion.core.single.FilterCalls'
    methods (C where it was built): they make the compiled call of the common case themselves
    and hand everything else to `_predict_general`, `_update_general` and `_step_general` below,
    the same results.
    """

    def __init__(self, motion: MotionModel, *, check: bool = True) -> None:
        super().__init__(motion, check=check)
        self._linear_only = False  # (KalmanFilter: update refuses a nonlinear measurement model)
        self._transitions = TransitionCache(motion) if motion.is_linear and isinstance(
            motion, LinearMotionModel) else None
        n = motion.ndim_state
        self._n, self._nn = n, (n, n)
        # Scratch of the compiled calls (measurements up to n + 2 components; a larger one takes
        # the numpy path): only ever read inside one call, which holds the GIL.
        self._ws = np.empty(_step.work_size(n, n + 2))
        self._plans: dict[MeasurementModel, StepPlan] = {}  # fusion.core.step_plan

    def __getstate__(self) -> dict[str, object]:
        """What a copy or a pickle takes: the attributes, with FilterCalls' fields (C fields where
        it was built, which are in no __dict__)."""
        return {**self.__dict__, "_transitions": self._transitions, "_plans": self._plans, "_check": self._check,
                "_linear_only": self._linear_only}

    def __setstate__(self, state: dict[str, object]) -> None:
        for name, value in state.items():
            setattr(self, name, value)

    @property
    def check(self) -> bool:
        """Whether inputs are validated; setting it drops the step plans (which carry the flag)."""
        return self._check

    @check.setter
    def check(self, on: bool) -> None:
        self._check = on = bool(on)
        self._plans = {}
        # the flags of update's compiled call with the model's R, and with a given one
        self._flags_model_R = _CHECK_Z if on else 0
        self._flags_given_R = _CHECK_Z | _CHECK_R if on else 0

    def _predict_general(self, state: GaussianState, t_ns: int, *, u: ArrayLike | None = None) -> GaussianState:
        """predict (FilterCalls) of any case: predict to t_ns (>= state.t_ns); u is the control
        input if the model takes one."""
        cache = self._transitions
        if cache is not None and u is None:
            d = t_ns - state.t_ns
            if d.__class__ is int and d >= 0:  # int times, forward: the one call (C where built)
                out = _predict(state.x, state.P, cache[d / NS_PER_S], t_ns, self._check)
                if out.__class__ is GaussianState:
                    return out
        t = int(t_ns)
        d = t - int(state.t_ns)
        dt = d / NS_PER_S if d >= 0 else dt_seconds(state.t_ns, t)  # (which raises TimeError)
        if cache is not None and u is None:  # what the call did not take, through numba's twin
            out = _predict_numba(state.x, state.P, cache[dt], t, self._check)
            if out.__class__ is GaussianState:
                return out
        return self._predict_numpy(state, t, dt, u)

    def _step_general(self, state: GaussianState, t_ns: int, z: ArrayLike, model: MeasurementModel, *,
                      R: ArrayLike | None = None, u: ArrayLike | None = None) -> Update:
        """step (FilterCalls) of any case: predict to t_ns, then fold z (taken at t_ns) in:
        update(predict(state, t_ns, u=u), z, model, R=R), the same Update bit for bit and the
        same errors.

        A linear motion model and a model with a compiled twin (linear for the KF), z a float64
        vector, no u: one compiled call. With the model's R, the call of the model's StepPlan
        (fusion.core.step_plan: F, Q, the model and R packed once per time step,
        fusion.core.single); with a given R (a float64 matrix), step_model
        (fusion.core.compiled_step), which checks it. Anything else, or anything the call
        refuses, is the two calls.
        """
        try:
            plan = self._plans[model]
        except (KeyError, TypeError):  # no plan yet, or a model that cannot be a key
            return self._step_unplanned(state, t_ns, z, model, R, u)
        if R is None and u is None and plan.R is model.R:
            t = int(t_ns)
            d = t - int(state.t_ns)
            packed = plan.blobs.get(d)
            if packed is None and d >= 0:
                packed = _blob(plan, d)
            if packed is not None:
                x, P = state.x, state.P
                out = _step_call(x, P, z, packed, t)
                if out.__class__ is Update:
                    return out
                if out == _NOT_TAKEN:
                    out = _step_numba(x, P, z, packed, t)
                    if out.__class__ is Update:
                        return out
                if out != _NOT_TAKEN:
                    return self.update(self.predict(state, t_ns), z, model)
        return self._step_unplanned(state, t_ns, z, model, R, u)

    def _fuses(self, model: MeasurementModel) -> bool:
        """Whether step may fold z in with model in the same compiled call as the predict."""
        return bool(model.kernel_kind) and self._transitions is not None

    def _step_unplanned(self, state: GaussianState, t_ns: int, z: ArrayLike, model: MeasurementModel,
                        R: ArrayLike | None, u: ArrayLike | None) -> Update:
        """step without a plan for this model: make one (then step with it) where it applies,
        step_model for a given R, else the two calls."""
        fuses = self._fuses(model) and u is None
        if fuses and R is None:
            try:
                plan = self._plans.get(model)
                stale = plan is None or plan.R is not model.R
            except TypeError:  # a model that cannot be a dict key: no plan
                stale = False
            if stale:
                if len(self._plans) >= 64:
                    self._plans.clear()
                plan = self._plans[model] = _make_plan(self._transitions, model, check=self.check)  # type: ignore[arg-type]
                if plan.R is model.R:  # (an R made afresh on every read would never find its plan)
                    return self.step(state, t_ns, z, model)
        kind = model.kernel_kind
        if fuses and R is not None and type(z) is _ndarray and z.dtype is _F64 and z.ndim == 1 and (
                type(R) is _ndarray and R.dtype is _F64 and R.ndim == 2):
            t = int(t_ns)
            d = t - int(state.t_ns)
            if d >= 0:
                m = model.ndim_meas
                xn, Pn, y, S = _empty(self._n), _empty(self._nn), _empty(m), _empty((m, m))
                code = kind << 2 | _CHECK_Z | _CHECK_R if self.check else kind << 2
                status, nis, ll = _step_model(code, state.x, state.P, self._transitions[d / NS_PER_S], z,  # type: ignore[index]
                                              model.kernel_spec, R, xn, Pn, y, S, self._ws)
                if status == 0:
                    return _new(Update, (_new(GaussianState, (xn, Pn, t)), y, S, nis, ll))
        return self.update(self.predict(state, t_ns, u=u), z, model, R=R)

    def _predict_numpy(self, state: GaussianState, t_ns: int, dt: float, u: ArrayLike | None) -> GaussianState:
        m = self._motion
        F = m.jacobian(state.x, dt)  # at the prior state
        x, P = _compiled.predict_linear(state.x, state.P, F, m.Q(state.x, dt))
        if not m.is_linear:
            x = m.f(state.x, dt)
        x = self._control(x, dt, u)
        self._finite(x)
        return GaussianState(x, P, int(t_ns))

    def _update_general(
        self, state: GaussianState, z: ArrayLike, model: MeasurementModel, *, R: ArrayLike | None = None
    ) -> Update:
        """update (FilterCalls) of any case: fold z (taken at state.t_ns) in; R defaults to the
        model's."""
        if self._linear_only and not model.is_linear:
            raise ConfigError(
                f"KalmanFilter needs a linear measurement model, got {type(model).__name__}; "
                "use ExtendedKalmanFilter or UnscentedKalmanFilter"
            )
        kind = model.kernel_kind
        if kind:
            if R is None:
                Ru = model.R
                code = kind << 2 | self._flags_model_R
            else:
                Ru = R
                code = kind << 2 | self._flags_given_R
            out = _update(code, state.x, state.P, z, model.kernel_spec, Ru, state.t_ns)
            if out.__class__ is Update:
                return out
            if out == _NOT_TAKEN:
                out = _update_numba(code, state.x, state.P, z, model.kernel_spec, Ru, state.t_ns)
                if out.__class__ is Update:
                    return out
        return self._update_numpy(state, z, model, R)

    def _update_numpy(self, state: GaussianState, z: ArrayLike, model: MeasurementModel,
                      R: ArrayLike | None) -> Update:
        zv, Rm = self._measurement(z, R, model)
        x = state.x
        y = model.residual(zv, model.h(x))
        xn, Pn, S, nis, ll = update_single(x, state.P, y, model.jacobian(x), Rm)
        return Update(GaussianState(xn, Pn, state.t_ns), y, S, nis, ll)


# Arguments that do not bind are refused by the general method a call was handed to: named as the
# method called (the message as before: "ExtendedKalmanFilter.predict() missing 1 required ...").
ExtendedKalmanFilter._predict_general.__qualname__ = "ExtendedKalmanFilter.predict"
ExtendedKalmanFilter._update_general.__qualname__ = "ExtendedKalmanFilter.update"
ExtendedKalmanFilter._step_general.__qualname__ = "ExtendedKalmanFilter.step"


class KalmanFilter(ExtendedKalmanFilter):
    """The linear Kalman filter: a linear motion model, linear measurement models only."""

    def __init__(self, motion: LinearMotionModel, *, check: bool = True) -> None:
        if not motion.is_linear:
            raise ConfigError(f"KalmanFilter needs a linear motion model, got {type(motion).__name__}")
        super().__init__(motion, check=check)
        self._linear_only = True  # update refuses a nonlinear measurement model

    def _fuses(self, model: MeasurementModel) -> bool:
        return model.is_linear and ExtendedKalmanFilter._fuses(self, model)
