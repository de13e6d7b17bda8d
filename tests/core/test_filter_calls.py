"""The filter's predict, update and step as C methods (fusion.core.single.FilterCalls) against
its general methods (`_predict_general`, `_update_general`, `_step_general`), which are what the
methods were before.

- over random states, time steps, z and every model of test_packed_step (hypothesis), validated
  or not, the methods return the same bits as the general methods;
- every case the C methods do not take themselves (a control input, a time step not yet cached,
  a time that is not an int or goes backwards, a given R, a model without a compiled twin, a
  nonlinear model given to the KF, a bad z, arguments by keyword or too many) gives the same
  result, or the same typed error with the same message, as the general methods;
- the filter's check flag and the KF's refusal of nonlinear models reach the C methods;
- the common case (a cached time step, a model with a compiled twin, no u, no R) never reaches
  the general methods: the C methods take it themselves;
- nothing is leaked or kept;
- a copied or pickled filter carries the fields the C methods read (and gives the same results);
- without the extension, FilterCallsPython's methods are the general methods.
"""

from __future__ import annotations

import copy
import gc
import pickle
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.core import single
from fusion.core.gaussian import GaussianState, Update
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter
from fusion.core.measurement import CartesianPosition
from fusion.core.motion import ConstantVelocity
from fusion.core.radar import Radar2D
from tests.core.test_packed_step import BUILT, MODELS, _filter, _start
from tests.core.test_single_c import traced_growth

needs_c = pytest.mark.skipif(not single.COMPILED, reason="the C extension was not built")


def _same_state(a: GaussianState, b: GaussianState) -> None:
    assert type(a) is GaussianState and type(b) is GaussianState
    assert a.t_ns == b.t_ns and type(a.t_ns) is type(b.t_ns)
    for u, v in ((a.x, b.x), (a.P, b.P)):
        assert u.shape == v.shape and u.dtype == v.dtype
        np.testing.assert_array_equal(u, v)


def _same(a: Update, b: Update) -> None:
    assert type(a) is Update and type(b) is Update
    _same_state(a.state, b.state)
    for u, v in ((a.y, b.y), (a.S, b.S)):
        np.testing.assert_array_equal(u, v)
    np.testing.assert_array_equal([a.nis, a.log_likelihood], [b.nis, b.log_likelihood])  # NaN == NaN


def _outcome(call, *args, **kwargs):
    """What call(*args, **kwargs) gives: its result, or its error's type and message."""
    try:
        return call(*args, **kwargs)
    except Exception as e:  # (compared, not swallowed)
        return type(e), str(e)


def _agree(a, b, what: str) -> None:
    try:
        if isinstance(a, Update):
            _same(a, b)
        elif isinstance(a, GaussianState):
            _same_state(a, b)
        else:
            assert a == b
    except AssertionError as e:
        raise AssertionError(f"{what}: {a!r} against {b!r}") from e


@needs_c
def test_the_filters_methods_are_the_c_ones() -> None:
    assert KalmanFilter.predict is single.FilterCalls.predict
    assert ExtendedKalmanFilter.update is single.FilterCalls.update
    assert single.FilterCalls is not single.FilterCallsPython


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       t0=st.integers(-(2**40), 2**40), dts=st.lists(st.integers(0, 3_000_000_000), min_size=1, max_size=8))
def test_the_methods_are_the_general_methods_bit_for_bit(name: str, check: bool, seed: int, t0: int,
                                                          dts: list[int]) -> None:
    rng = np.random.default_rng(seed)
    meas = BUILT[name]
    f = _filter(meas, check)
    s = _start(meas.ndim_state, rng, t0)
    for dt in dts:
        t = s.t_ns + dt
        for _ in range(2):  # the first predict to a new time step fills the cache, the second reads it
            p = f.predict(s, t)
            _same_state(p, f._predict_general(s, t))
        z = meas.h(p.x) + rng.normal(0.0, 1.0, meas.ndim_meas)
        u = f.update(p, z, meas)
        _same(u, f._update_general(p, z, meas))
        for _ in range(2):  # the first step of a time step makes its plan's blob, the second reads it
            _same(f.step(s, t, z, meas), u)
            _same(f._step_general(s, t, z, meas), u)
        s = u.state


def test_every_case_the_c_methods_hand_on_agrees_with_the_general_methods() -> None:
    rng = np.random.default_rng(7)
    cv = ConstantVelocity(ndim=2, q=0.5)
    pos = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    radar = Radar2D(R=[4.0, 1e-4])
    ctl = ConstantVelocity(ndim=2, q=0.5, with_control=True)

    class Moved(CartesianPosition):  # a subclass that changes h: no compiled twin
        pass

    moved = Moved(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    kf, ekf, kfc = KalmanFilter(cv), ExtendedKalmanFilter(cv), KalmanFilter(ctl)
    s = _start(4, rng, 1_000)
    t = s.t_ns + 100_000_000
    kf.predict(s, t)  # cached
    z = np.array([s.x[0] + 1.0, s.x[2] - 1.0])
    zr = radar.h(s.x) + np.array([1.0, 1e-3])
    predicts = {
        "u": (kfc, (s, t), {"u": [1.0, -1.0]}),
        "u None by keyword": (kf, (s, t), {"u": None}),
        "a new time step": (kf, (s, t + 12_345), {}),
        "t a numpy int": (kf, (s, np.int64(t)), {}),
        "t a float": (kf, (s, float(t)), {}),
        "t a bool": (kf, (GaussianState(s.x, s.P, 0), True), {}),
        "t backwards": (kf, (s, s.t_ns - 1), {}),
        "t far ahead": (kf, (s, s.t_ns + 2**60), {}),
        "t beyond int64": (kf, (s, 2**70), {}),
        "by keyword": (kf, (), {"state": s, "t_ns": t}),
        "a tuple for a state": (kf, (tuple(s), t), {}),
        "too many": (kf, (s, t, None), {}),
        "too few": (kf, (s,), {}),
        "an unknown keyword": (kf, (s, t), {"v": 1}),
        "x not finite": (kf, (GaussianState(np.full(4, np.nan), s.P, s.t_ns), t), {}),
    }
    for what, (f, args, kw) in predicts.items():
        _agree(_outcome(f.predict, *args, **kw), _outcome(f._predict_general, *args, **kw), what)
    p = kf.predict(s, t)
    updates = {
        "R given": (kf, (p, z, pos), {"R": 2.0 * np.eye(2)}),
        "R given asymmetric": (kf, (p, z, pos), {"R": np.array([[1.0, 0.5], [0.0, 1.0]])}),
        "no compiled twin": (kf, (p, z, moved), {}),
        "radar to the KF": (kf, (p, zr, radar), {}),
        "radar to the EKF": (ekf, (p, zr, radar), {}),
        "z a list": (kf, (p, list(z), pos), {}),
        "z float32": (kf, (p, z.astype(np.float32), pos), {}),
        "z NaN": (kf, (p, np.array([np.nan, 0.0]), pos), {}),
        "z too long": (kf, (p, np.zeros(3), pos), {}),
        "not a model": (kf, (p, z, object()), {}),
        "by keyword": (kf, (), {"state": p, "z": z, "model": pos}),
        "too many": (kf, (p, z, pos, None), {}),
    }
    for what, (f, args, kw) in updates.items():
        _agree(_outcome(f.update, *args, **kw), _outcome(f._update_general, *args, **kw), what)
    kf.step(s, t, z, pos)  # a plan for pos with the blob of 0.1 s
    steps = {
        "R given": (kf, (s, t, z, pos), {"R": 2.0 * np.eye(2)}),
        "u": (kfc, (s, t, z, pos), {"u": [1.0, -1.0]}),
        "no plan yet": (ekf, (s, t, zr, radar), {}),
        "a new time step": (kf, (s, t + 7, z, pos), {}),
        "t a numpy int": (kf, (s, np.int64(t), z, pos), {}),
        "t backwards": (kf, (s, s.t_ns - 1, z, pos), {}),
        "no compiled twin": (kf, (s, t, z, moved), {}),
        "radar to the KF": (kf, (s, t, zr, radar), {}),
        "z a list": (kf, (s, t, list(z), pos), {}),
        "z NaN": (kf, (s, t, np.array([np.nan, 0.0]), pos), {}),
        "by keyword": (kf, (), {"state": s, "t_ns": t, "z": z, "model": pos}),
        "too few": (kf, (s, t, z), {}),
        "not a model": (kf, (s, t, z, object()), {}),
    }
    for what, (f, args, kw) in steps.items():
        _agree(_outcome(f.step, *args, **kw), _outcome(f._step_general, *args, **kw), what)
    assert _outcome(kf.predict, s) == (TypeError, "ExtendedKalmanFilter.predict() missing 1 required positional "
                                                  "argument: 't_ns'")
    assert _outcome(kf.update, p, z, pos, R=None, Q=1)[1].startswith("ExtendedKalmanFilter.update() got an unexpected")
    assert _outcome(kf.step, s, t) == (TypeError, "ExtendedKalmanFilter.step() missing 2 required positional "
                                                 "arguments: 'z' and 'model'")
    assert _outcome(kf.update, p, zr, radar)[0].__name__ == "ConfigError"
    assert _outcome(kf.predict, s, s.t_ns - 1)[0].__name__ == "TimeError"


def test_the_check_flag_reaches_the_methods() -> None:
    cv = ConstantVelocity(ndim=2, q=0.5)
    pos = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    f = KalmanFilter(cv)
    s = _start(4, np.random.default_rng(3))
    bad = np.array([np.inf, 0.0])
    with pytest.raises(Exception, match="z"):
        f.update(s, bad, pos)
    f.check = False
    assert f.check is False and not f._check
    assert not np.isfinite(f.update(s, bad, pos).state.x).all()  # not checked: inf goes through
    f.check = 1
    assert f.check is True
    with pytest.raises(Exception, match="z"):
        f.update(s, bad, pos)
    nan_state = GaussianState(np.full(4, np.nan), s.P, 0)
    with pytest.raises(Exception, match="non-finite"):
        f.predict(nan_state, 100)
    f.check = False
    assert np.isnan(f.predict(nan_state, 100).x).all()


def test_the_python_twin_is_the_general_methods() -> None:
    """What an install without a C compiler runs: FilterCallsPython's methods hand every call to
    the general methods."""
    rng = np.random.default_rng(11)
    meas = BUILT["radar"]
    f = _filter(meas, True)
    s = _start(4, rng)
    t = s.t_ns + 250_000_000
    p = single.FilterCallsPython.predict(f, s, t)
    _same_state(p, f._predict_general(s, t))
    z = meas.h(p.x) + np.array([1.0, 1e-3])
    _same(single.FilterCallsPython.update(f, p, z, meas), f._update_general(p, z, meas))
    _same(single.FilterCallsPython.update(f, p, z, meas, R=2.0 * meas.R), f._update_general(p, z, meas, R=2.0 * meas.R))


class _Counting(KalmanFilter):
    """A KF that counts the calls its C methods hand to the general methods."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.handed: list[str] = []

    def _predict_general(self, *args, **kwargs):
        self.handed.append("predict")
        return super()._predict_general(*args, **kwargs)

    def _update_general(self, *args, **kwargs):
        self.handed.append("update")
        return super()._update_general(*args, **kwargs)

    def _step_general(self, *args, **kwargs):
        self.handed.append("step")
        return super()._step_general(*args, **kwargs)


@needs_c
@pytest.mark.parametrize("check", [True, False])
def test_the_common_case_is_taken_in_c(check: bool) -> None:
    """A cached time step and a model with a compiled twin (for step, its plan's blob of the time
    step) never reach the general methods, validated or not (unvalidated, a z with inf in it goes
    through as it is)."""
    pos = CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])
    f = _Counting(ConstantVelocity(ndim=2, q=0.5), check=check)
    s = _start(4, np.random.default_rng(5))
    f.predict(s, s.t_ns + 100_000_000)
    assert f.handed == ["predict"]  # the first step of 0.1 s fills the cache
    f.handed.clear()
    for k in range(1, 20):
        s = f.update(f.predict(s, s.t_ns + 100_000_000), np.array([1.0 * k, -1.0 * k]), pos).state
    assert f.handed == []
    if not check:
        assert not np.isfinite(f.update(s, np.array([np.inf, 0.0]), pos).state.x).all()
        assert f.handed == []
    f.step(s, s.t_ns + 100_000_000, np.array([1.0, 2.0]), pos)
    assert set(f.handed) == {"step"}  # the first step makes the plan and its blob of 0.1 s
    f.handed.clear()
    for k in range(1, 20):
        s = f.step(s, s.t_ns + 100_000_000, np.array([1.0 * k, -1.0 * k]), pos).state
    assert f.handed == []
    f.update(s, np.array([1.0, 2.0]), pos, R=np.eye(2))
    f.predict(s, s.t_ns + 1)
    f.step(s, s.t_ns + 1, np.array([1.0, 2.0]), pos)
    assert f.handed[:2] == ["update", "predict"] and f.handed[2] == "step"


@needs_c
def test_nothing_is_leaked_or_kept() -> None:
    """The methods' calls, taken in C or handed on, failing or not, leave every input's reference
    count as it was and allocate nothing that stays."""
    meas = BUILT["radar"]
    f = _filter(meas, True)
    rng = np.random.default_rng(19)
    s = _start(4, rng, 10**15)  # a large int time: one object, its count checked
    t = s.t_ns + 100_000_000
    p = f.predict(s, t)
    z = meas.h(p.x) + 0.1
    bad = np.array([np.nan, 0.0])
    FQ = f._transitions[0.1]  # (white-box: the filter's transitions)
    ins = (s, s.x, s.P, s.t_ns, t, p, z, FQ, meas, meas.kernel_spec, meas.R)

    def calls() -> None:
        f.predict(s, t)
        f.update(p, z, meas)
        f.predict(s, t + 1)  # a second time step: handed on the first time, then cached
        f.update(p, z, meas, R=meas.R)
        f.step(s, t, z, meas)
        f.step(s, t, z, meas, R=meas.R)
        _outcome(f.update, p, bad, meas)  # (the errors are test_every_case...'s)
        _outcome(f.predict, s, s.t_ns - 1)
        _outcome(f.predict, s)

    calls()  # the step's plan for meas is made: it holds meas (a key) and meas.R
    gc.collect()
    before = [sys.getrefcount(o) for o in ins]
    for _ in range(300):
        calls()
    gc.collect()
    assert [sys.getrefcount(o) for o in ins] == before
    grown = traced_growth(calls, warm=300, n=3_000)
    assert grown < 20_000, grown
    assert [sys.getrefcount(o) for o in ins] == before


@pytest.mark.parametrize("how", ["copy", "deepcopy", "pickle"])
def test_a_copied_or_pickled_filter_is_the_same_filter(how: str) -> None:
    """The fields the C methods read (FilterCalls': in no __dict__ where it was built) go with a
    copy and a pickle, as every attribute did when the filter was a plain Python class."""
    rng = np.random.default_rng(23)
    for meas in (BUILT["radar"], CartesianPosition(ndim_state=4, indices=(0, 2), R=[1.0, 1.0])):
        for check in (True, False):
            f = _filter(meas, check)
            s = _start(4, rng)
            t = s.t_ns + 100_000_000
            f.predict(s, t)  # a cached step goes with it
            g = {"copy": copy.copy, "deepcopy": copy.deepcopy,
                 "pickle": lambda o: pickle.loads(pickle.dumps(o))}[how](f)
            assert type(g) is type(f) and g.check is check and g._linear_only is f._linear_only
            assert (g._transitions is f._transitions) is (how == "copy")
            assert 0.1 in g._transitions
            p = g.predict(s, t)
            _same_state(p, f.predict(s, t))
            z = meas.h(p.x) + 0.5
            _same(g.update(p, z, meas), f.update(p, z, meas))
            _same(g.step(s, t, z, meas), f.step(s, t, z, meas))
            bad = np.array([np.nan, 0.0])  # refused where checked, through where not
            _agree(_outcome(g.update, p, bad, meas), _outcome(f.update, p, bad, meas), "a bad z")
