"""The planned step (fusion.core.step_plan, fusion.core.compiled_packed) against predict then update.

- over random states, time steps, measurements and models (hypothesis), KF and EKF, validated
  or not, step gives the bits of predict then update (whose update is compiled_step's kernel,
  a different code path from the packed one), including after many distinct time steps
  (the plan's bounded store);
- bad inputs are refused with the error class and message of the two calls: NaN or inf in z, z
  of the wrong length or shape, a time step backwards, a non-finite prediction, S not positive
  definite;
- the returned arrays are fresh: they share no memory with the inputs, the model or each other,
  and writing into them changes neither the next step nor the inputs;
- a plan follows its model and filter: a model given a new R, a filter whose check is switched,
  a model's R cannot be changed in place.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.core.gaussian import GaussianState, Update
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition
from fusion.core.motion import ConstantAcceleration, ConstantVelocity
from fusion.core.radar import Radar2D
from fusion.errors import NonFiniteError, NumericalError, ShapeError, TimeError

NAN, INF = float("nan"), float("inf")
MODELS = {
    "cart_2d": lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.01, 0.02]),
    "cart_1d": lambda: CartesianPosition(ndim_state=4, indices=(2,), R=[0.3]),
    "cart_2d_posed": lambda: CartesianPosition(ndim_state=4, indices=(0, 2), R=[[1.0, 0.3], [0.3, 2.0]],
                                               position=[120.0, -40.0], heading_rad=0.7),
    "cart_3d_posed": lambda: CartesianPosition(ndim_state=6, indices=(0, 2, 4), R=[1.0, 2.0, 3.0],
                                               position=[10.0, 20.0, 5.0], heading_rad=-1.1, pitch_rad=0.2,
                                               roll_rad=0.05),
    "cart_ca_3d": lambda: CartesianPosition(ndim_state=9, indices=(0, 3, 6), R=[1.0, 2.0, 3.0]),
    "radar": lambda: Radar2D(R=[100.0, 1e-4]),
    "radar_rr": lambda: Radar2D(R=[25.0, 1e-4, 0.25], range_rate=True, position=[-50.0, 80.0], heading_rad=-3.0),
}
BUILT = {name: make() for name, make in MODELS.items()}


def _motion(meas: CartesianPosition | Radar2D) -> ConstantVelocity | ConstantAcceleration:
    n = meas.ndim_state
    return ConstantAcceleration(ndim=3, q=0.2) if n == 9 else ConstantVelocity(ndim=n // 2, q=0.5)


def _filter(meas: CartesianPosition | Radar2D, check: bool) -> ExtendedKalmanFilter:
    cls = KalmanFilter if meas.is_linear else ExtendedKalmanFilter
    return cls(_motion(meas), check=check)


def _same(a: Update, b: Update) -> None:
    assert a.state.t_ns == b.state.t_ns and type(a.state.t_ns) is int
    for u, v in ((a.state.x, b.state.x), (a.state.P, b.state.P), (a.y, b.y), (a.S, b.S)):
        assert u.shape == v.shape and u.dtype == v.dtype
        np.testing.assert_array_equal(u, v)
    np.testing.assert_array_equal([a.nis, a.log_likelihood], [b.nis, b.log_likelihood])  # NaN == NaN


def _start(n: int, rng: np.random.Generator, t_ns: int = 0) -> GaussianState:
    x = rng.normal(0.0, 10.0, n)
    x[0] += 1000.0  # away from a radar at (or near) the origin
    A = rng.standard_normal((n, n))
    return GaussianState.create(x, rng.uniform(0.1, 100.0) * (A @ A.T + 0.5 * np.eye(n)), t_ns=t_ns)


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       t0=st.integers(-(2**40), 2**40), dts=st.lists(st.integers(0, 3_000_000_000), min_size=1, max_size=8))
def test_step_is_predict_then_update_bit_for_bit(name: str, check: bool, seed: int, t0: int, dts: list[int]) -> None:
    rng = np.random.default_rng(seed)
    meas = BUILT[name]
    f = _filter(meas, check)
    a = b = _start(meas.ndim_state, rng, t0)
    for dt in dts:
        t = a.t_ns + dt
        z = meas.h(f.predict(a, t).x) + rng.normal(0.0, 1.0, meas.ndim_meas)
        fused, two = f.step(a, t, z, meas), f.update(f.predict(b, t), z, meas)
        _same(fused, two)
        a, b = fused.state, two.state


def test_many_time_steps_through_a_bounded_plan() -> None:
    """More distinct time steps than a plan keeps: still the bits of the two calls."""
    rng = np.random.default_rng(3)
    meas = BUILT["radar"]
    f = ExtendedKalmanFilter(ConstantVelocity(ndim=2, q=0.5))
    a = b = _start(4, rng)
    for k in range(600):
        t = a.t_ns + 1_000_000 + 7919 * k
        z = meas.h(f.predict(a, t).x) + rng.normal(0.0, [1.0, 1e-3])
        fused, two = f.step(a, t, z, meas), f.update(f.predict(b, t), z, meas)
        _same(fused, two)
        a, b = fused.state, two.state
    plan = f._plans[meas]  # the filter's own store (white-box: the bound)
    assert len(plan.blobs) <= plan.max_entries


def _error_of(call) -> tuple[type, str]:
    with pytest.raises(Exception) as info:  # any: class and message compared below
        call()
    return type(info.value), str(info.value)


BAD = {
    "z_nan": (np.array([1000.0, NAN]), NonFiniteError),
    "z_inf": (np.array([INF, 0.0]), NonFiniteError),
    "z_long": (np.array([1000.0, 0.0, 1.0]), ShapeError),
    "z_short": (np.array([1000.0]), ShapeError),
    "z_matrix": (np.array([[1000.0, 0.0]]), ShapeError),
}


@pytest.mark.parametrize(("model", "case"), list(itertools.product(("cart_2d", "radar"), BAD)))
def test_bad_z_refused_as_by_the_two_calls(model: str, case: str) -> None:
    z, err = BAD[case]
    meas = BUILT[model]
    f = _filter(meas, True)
    st0 = GaussianState.create([1000.0, 0.0, 10.0, 0.0], np.eye(4), t_ns=5)
    f.step(st0, 100, meas.h(st0.x), meas)  # the plan exists: the refusal is the planned path's
    fused = _error_of(lambda: f.step(st0, 100, z, meas))
    assert fused == _error_of(lambda: f.update(f.predict(st0, 100), z, meas))
    assert fused[0] is err


def test_time_backwards_nonfinite_prediction_and_S_not_pd() -> None:
    meas = BUILT["cart_2d"]
    kf = KalmanFilter(ConstantVelocity(ndim=2, q=1.0))
    good = GaussianState.create([0.0, 0.0, 1.0, 0.0], np.eye(4), t_ns=1_000)
    kf.step(good, 2_000, np.zeros(2), meas)
    cases = {
        "backwards": (good, 999, TimeError),
        "nonfinite": (GaussianState(np.array([NAN, 0.0, 0.0, 0.0]), np.eye(4), 0), 1_000, NumericalError),
        "S_not_pd": (GaussianState(np.zeros(4), -10.0 * np.eye(4), 0), 1_000, NumericalError),
    }
    for state, t, err in cases.values():
        fused = _error_of(lambda state=state, t=t: kf.step(state, t, np.zeros(2), meas))
        assert fused == _error_of(lambda state=state, t=t: kf.update(kf.predict(state, t), np.zeros(2), meas))
        assert fused[0] is err


def test_returned_arrays_are_fresh_and_independent() -> None:
    rng = np.random.default_rng(5)
    for meas in (BUILT["cart_2d"], BUILT["radar"]):
        f = _filter(meas, True)
        s = _start(4, rng)
        z = meas.h(s.x) + 0.1
        x0, P0, z0, R0 = s.x.copy(), s.P.copy(), z.copy(), meas.R.copy()
        up = f.step(s, s.t_ns + 10**8, z, meas)
        ref = f.update(f.predict(s, s.t_ns + 10**8), z, meas)
        out = (up.state.x, up.state.P, up.y, up.S)
        for a, b in itertools.combinations((*out, s.x, s.P, z, meas.R, meas.kernel_spec), 2):
            assert not np.shares_memory(a, b)
        assert all(a.base is None and a.flags.writeable and a.flags.c_contiguous for a in out)
        for a in out:
            a[...] = 12345.0  # the caller owns them: writing changes nothing the filter keeps
        np.testing.assert_array_equal(s.x, x0)
        np.testing.assert_array_equal(s.P, P0)
        np.testing.assert_array_equal(z, z0)
        np.testing.assert_array_equal(meas.R, R0)
        _same(f.step(s, s.t_ns + 10**8, z, meas), ref)


def test_plan_follows_a_new_R_and_the_check_flag() -> None:
    rng = np.random.default_rng(9)
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    kf = KalmanFilter(ConstantVelocity(ndim=2, q=1.0), check=False)
    s = _start(4, rng)
    z = meas.h(s.x) + 0.5
    kf.step(s, 10**8, z, meas)
    with pytest.raises(ValueError, match="read-only"):
        meas.R[0, 0] = 2.0
    meas.R = np.array([[4.0, 0.0], [0.0, 9.0]])  # a new R: a new plan
    _same(kf.step(s, 10**8, z, meas), kf.update(kf.predict(s, 10**8), z, meas))
    assert np.isnan(kf.step(s, 10**8, np.array([NAN, 0.0]), meas).state.x).any()  # check off: NaN in, NaN out
    kf.check = True
    with pytest.raises(NonFiniteError, match="z holds NaN or inf"):
        kf.step(s, 10**8, np.array([NAN, 0.0]), meas)


class FreshR(Radar2D):
    """A model that opts into the compiled twin but makes its R afresh on every read."""

    kernel_kind = Radar2D.kernel_kind

    @property
    def R(self) -> np.ndarray:  # type: ignore[override]
        return np.diag([100.0, 1e-4])

    @R.setter
    def R(self, value: np.ndarray) -> None:
        pass


def test_a_model_whose_R_is_made_afresh_takes_the_two_calls() -> None:
    meas = FreshR(R=[100.0, 1e-4])
    f = ExtendedKalmanFilter(ConstantVelocity(ndim=2, q=0.5))
    s = _start(4, np.random.default_rng(2))
    z = meas.h(s.x)
    for _ in range(3):
        _same(f.step(s, 10**8, z, meas), f.update(f.predict(s, 10**8), z, meas))
