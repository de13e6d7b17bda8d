"""The C calls of fusion.core.single (the extension fusion.core._single) against their numba twins.

- the install built it wherever a C compiler is on the PATH (CI's machine has one; without one
  the package still installs and the filters run the twins, which the rest of the suite then
  tests);
- over random states, time steps, z and every model of test_packed_step (hypothesis), validated
  or not, with the model's R or a given one (symmetric, slightly asymmetric, asymmetric,
  indefinite), predict, update and step return the same bits and the same status as numba's
  predict_fq, update_model and step_packed, including NaN and inf in z, x or R and an S that is
  not positive definite;
- strided and Fortran-ordered inputs are read right; what a call does not take (a byte-swapped
  or unaligned array, z not a float64 vector, a non-int time) it hands back as NOT_TAKEN, and
  the filter then gives the same bits through the twin or its general path;
- a blob too short for the sizes it names, or inputs of the wrong sizes, are SHAPE, not a read
  past an end;
- nothing is leaked or kept: the results are freed with the Update, the inputs' reference counts
  are unchanged, and many calls, failing or not, allocate nothing that stays.
"""

from __future__ import annotations

import gc
import shutil
import sys
import sysconfig
import tracemalloc
import weakref
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.core import single
from fusion.core.compiled_step import CHECK_R, CHECK_Z, SHAPE
from fusion.core.gaussian import GaussianState, Update
from fusion.core.step_plan import blob, make_plan
from fusion.core.transitions import TransitionCache
from tests.core.test_packed_step import BUILT, MODELS, _filter, _motion, _same, _start

needs_c = pytest.mark.skipif(not single.COMPILED, reason="the C extension was not built")
NAN, INF = float("nan"), float("inf")


def _c_compiler() -> str | None:
    cc = (sysconfig.get_config_var("CC") or "cc").split()[0]
    return shutil.which(cc)


@pytest.mark.skipif(not single.COMPILED and _c_compiler() is None,
                    reason="no C compiler here: the filters run the numba twins")
def test_the_install_built_the_c_extension() -> None:
    """Where there is a C compiler, pip install must have built the extension (setup.py makes it
    optional, so a failed build would otherwise pass unseen)."""
    assert single.COMPILED, (f"fusion.core._single is missing though {_c_compiler()} is here: "
                             "see the build's output of pip install -v -e .")
    assert single.step is not single.step_numba and single.update is not single.update_numba


def _blob(name: str, check: bool, dt_ns: int) -> np.ndarray:
    meas = BUILT[name]
    return blob(make_plan(TransitionCache(_motion(meas)), meas, check=check), dt_ns)


def _agree(c: object, nb: object) -> None:
    """The same status, or the same bits and types."""
    if isinstance(nb, int):
        assert c == nb and type(c) is int
        return
    assert type(c) is type(nb) and isinstance(c, GaussianState | Update)
    if isinstance(c, Update):
        assert type(c.state) is GaussianState
        _same(c, nb)  # type: ignore[arg-type]
    else:
        assert c.t_ns == nb.t_ns and type(c.t_ns) is int  # type: ignore[union-attr]
        for u, v in ((c.x, nb.x), (c.P, nb.P)):  # type: ignore[union-attr]
            assert u.shape == v.shape and u.flags.c_contiguous
            np.testing.assert_array_equal(u, v)


SPOILS = ["none", "z_nan", "z_inf", "x_nan", "P_neg", "z_huge"]
R_KINDS = ["model", "given", "nearly_symmetric", "just_asymmetric", "asymmetric", "indefinite", "R_nan"]


def _inputs(name: str, seed: int, spoil: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    meas = BUILT[name]
    s = _start(meas.ndim_state, rng)
    x, P = s.x.copy(), s.P.copy()
    z = meas.h(x) + rng.normal(0.0, 3.0, meas.ndim_meas)
    if spoil == "z_nan":
        z[-1] = NAN
    elif spoil == "z_inf":
        z[0] = -INF
    elif spoil == "x_nan":
        x[1] = NAN
    elif spoil == "P_neg":
        P = -P
    elif spoil == "z_huge":
        z *= 1e300
    return x, P, z


def _R(name: str, kind: str, rng: np.random.Generator) -> np.ndarray:
    R = np.array(BUILT[name].R, dtype=np.float64)
    m = R.shape[0]
    if kind == "model":
        return BUILT[name].R
    A = rng.standard_normal((m, m))
    R = A @ A.T + 0.1 * np.eye(m)
    if kind == "nearly_symmetric":  # inside as_covariance's tolerance (1e-9 of the largest entry)
        R[0, -1] += 1e-12 * np.abs(R).max()
    elif kind == "just_asymmetric" and m > 1:  # just outside it
        R[0, -1] += 1e-8 * np.abs(R).max()
    elif kind == "asymmetric" and m > 1:
        R[0, -1] += 0.5
    elif kind == "indefinite":
        R = -R
    elif kind == "R_nan":
        R[0, 0] = NAN
    return R


@needs_c
@settings(max_examples=80, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       dt_ns=st.integers(0, 5_000_000_000), t=st.integers(-(2**62), 2**62), spoil=st.sampled_from(SPOILS))
def test_step_gives_the_bits_and_status_of_numba(name: str, check: bool, seed: int, dt_ns: int, t: int,
                                                 spoil: str) -> None:
    x, P, z = _inputs(name, seed, spoil)
    b = _blob(name, check, dt_ns)
    c = single.step(x, P, z, b, t)
    _agree(c, single.step_numba(x, P, z, b.copy(), t))  # its own scratch: the same blob contents
    if not isinstance(c, int):
        assert c.state.t_ns == t


@needs_c
@settings(max_examples=80, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       dt_ns=st.integers(0, 5_000_000_000), t=st.integers(-(2**62), 2**62), spoil=st.sampled_from(SPOILS))
def test_predict_gives_the_bits_and_status_of_numba(name: str, check: bool, seed: int, dt_ns: int, t: int,
                                                    spoil: str) -> None:
    x, P, _ = _inputs(name, seed, spoil)
    FQ = TransitionCache(_motion(BUILT[name]))[dt_ns / 1e9]
    c = single.predict(x, P, FQ, t, check)
    _agree(c, single.predict_numba(x, P, FQ, t, check))
    if spoil == "x_nan":
        assert c == 1 if check else np.isnan(c.x).any()  # type: ignore[union-attr]


@needs_c
@settings(max_examples=120, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       t=st.integers(-(2**62), 2**62), spoil=st.sampled_from(SPOILS), r_kind=st.sampled_from(R_KINDS))
def test_update_gives_the_bits_and_status_of_numba(name: str, check: bool, seed: int, t: int, spoil: str,
                                                   r_kind: str) -> None:
    x, P, z = _inputs(name, seed, spoil)
    meas = BUILT[name]
    R = _R(name, r_kind, np.random.default_rng(seed + 1))
    flags = (CHECK_Z | (CHECK_R if r_kind != "model" else 0)) if check else 0
    code = meas.kernel_kind << 2 | flags
    c = single.update(code, x, P, z, meas.kernel_spec, R, t)
    _agree(c, single.update_numba(code, x, P, z, meas.kernel_spec, R, t))


@needs_c
@pytest.mark.parametrize("name", sorted(MODELS))
def test_strided_and_fortran_inputs_read_right(name: str) -> None:
    rng = np.random.default_rng(11)
    meas = BUILT[name]
    s = _start(meas.ndim_state, rng)
    n, m = meas.ndim_state, meas.ndim_meas
    z = meas.h(s.x) + 0.3
    wide = np.zeros((3 * n, 2))
    wide[::3, 1] = s.x  # x as a view with a stride of 48 bytes
    xs = wide[::3, 1]
    zs = np.zeros(2 * m)
    zs[::2] = z
    Pf, Rf = np.asfortranarray(s.P), np.asfortranarray(meas.R)
    b = _blob(name, True, 250_000_000)
    ref = single.step(s.x, s.P, z, b, 7)
    assert isinstance(ref, Update)
    _same(single.step(xs, Pf, zs[::2], b, 7), ref)  # type: ignore[arg-type]
    FQ = TransitionCache(_motion(meas))[0.25]
    ref_p = single.predict(s.x, s.P, FQ, 7, True)
    _agree(single.predict(xs, Pf, FQ, 7, True), ref_p)
    code = meas.kernel_kind << 2 | CHECK_Z | CHECK_R
    ref_u = single.update(code, s.x, s.P, z, meas.kernel_spec, meas.R, 7)
    assert isinstance(ref_u, Update)
    _same(single.update(code, xs, Pf, zs[::2], meas.kernel_spec, Rf, 7), ref_u)  # type: ignore[arg-type]


def _unaligned(a: np.ndarray) -> np.ndarray:
    raw = np.zeros(a.nbytes + 1, dtype=np.uint8)
    out = raw[1:].view(a.dtype).reshape(a.shape)
    out[...] = a
    assert not out.flags.aligned
    return out


@needs_c
def test_what_a_call_does_not_take_is_not_taken_and_the_filter_still_agrees() -> None:
    rng = np.random.default_rng(13)
    meas = BUILT["radar"]
    f = _filter(meas, True)
    s = _start(4, rng)
    t = s.t_ns + 100_000_000
    z = meas.h(f.predict(s, t).x) + np.array([1.0, 1e-3])
    f.step(s, t, z, meas)  # the plan exists
    b = f._plans[meas].blobs[100_000_000]  # the filter's own blob (white-box: handed to the call)
    FQ = f._transitions[0.1]  # (white-box: the filter's transitions)
    code = meas.kernel_kind << 2 | CHECK_Z
    swapped = s.x.astype(s.x.dtype.newbyteorder())
    cases = {
        "x byte-swapped": (swapped, s.P, z, t),
        "P unaligned": (s.x, _unaligned(s.P), z, t),
        "z float32": (s.x, s.P, z.astype(np.float32), t),
        "z a list": (s.x, s.P, list(z), t),
        "z a matrix": (s.x, s.P, z[None, :], t),
        "t a float": (s.x, s.P, z, float(t)),
        "t a numpy int": (s.x, s.P, z, np.int64(t)),
    }
    for what, (x, P, zz, tt) in cases.items():
        assert single.step(x, P, zz, b, tt) == single.NOT_TAKEN, what
        assert single.update(code, x, P, zz, meas.kernel_spec, meas.R, tt) == single.NOT_TAKEN, what
        if what.startswith(("x", "P", "t")):
            assert single.predict(x, P, FQ, tt, True) == single.NOT_TAKEN, what
    assert single.update(code, s.x, s.P, z, meas.kernel_spec, list(meas.R), t) == single.NOT_TAKEN
    assert single.update(-1, s.x, s.P, z, meas.kernel_spec, meas.R, t) == single.NOT_TAKEN
    two = f.update(f.predict(s, t), z, meas)
    odd = GaussianState(s.x, _unaligned(s.P), s.t_ns)  # through the numba twins
    _same(f.step(odd, t, z, meas), two)
    _same(f.update(f.predict(odd, t), z, meas), two)
    _same(f.step(s, np.int64(t), z, meas), two)
    _same(f.step(s, t, list(z), meas), two)
    _same(f.update(f.predict(s, t), list(z), meas), two)


@needs_c
def test_a_blob_too_short_or_the_wrong_sizes_are_shape_not_a_read_past_an_end() -> None:
    b = _blob("cart_2d", True, 100_000_000)
    x, P, z = np.zeros(4), np.eye(4), np.zeros(2)
    assert isinstance(single.step(x, P, z, b, 0), Update)
    for cut in (0, 3, 4, 20, len(b) - 1):
        assert single.step(x, P, z, b[:cut].copy(), 0) == SHAPE
    assert single.step(np.zeros(6), np.eye(6), z, b, 0) == SHAPE
    assert single.step(x, P, np.zeros(3), b, 0) == SHAPE
    FQ = TransitionCache(_motion(BUILT["cart_2d"]))[0.1]
    assert single.predict(np.zeros(6), np.eye(6), FQ, 0, True) == SHAPE
    assert single.predict(x, np.eye(5), FQ, 0, True) == SHAPE
    meas = BUILT["cart_2d"]
    code = meas.kernel_kind << 2 | CHECK_Z
    spec, R = meas.kernel_spec, meas.R
    assert isinstance(single.update(code, x, P, z, spec, R, 0), Update)
    assert single.update(code, x, P, np.zeros(3), spec, R, 0) == SHAPE
    assert single.update(code, x, P, np.zeros(3), spec, np.eye(3), 0) == SHAPE  # the spec names 2
    assert single.update(code, np.zeros(6), np.eye(6), z, spec, R, 0) == SHAPE
    assert single.update(code, x, P, z, spec[:-1].copy(), R, 0) == SHAPE
    assert single.update(code, x, P, np.zeros(0), spec, np.zeros((0, 0)), 0) == SHAPE
    with pytest.raises(TypeError, match="5 arguments"):
        single.step(x, P, z, b)
    with pytest.raises(TypeError, match="7 arguments"):
        single.update(code, x, P, z, spec, R)
    from fusion.core import _single

    with pytest.raises(TypeError):
        _single.bind(int, Update)


@needs_c
def traced_growth(calls: Callable[[], None], *, warm: int, n: int) -> int:
    """Bytes of memory tracemalloc sees held more after n calls() than after `warm` of them
    (garbage collected before each reading)."""
    gc.collect()
    tracemalloc.start()
    try:
        for _ in range(warm):
            calls()
        gc.collect()
        base, _ = tracemalloc.get_traced_memory()
        for _ in range(n):
            calls()
        gc.collect()
        return tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()


def test_nothing_is_leaked_or_kept() -> None:
    meas = BUILT["radar_rr"]
    b = _blob("radar_rr", True, 100_000_000)
    FQ = TransitionCache(_motion(meas))[0.1]
    rng = np.random.default_rng(17)
    s = _start(4, rng)
    x, P = s.x, s.P
    z = meas.h(x) + 0.1
    spec, R = meas.kernel_spec, meas.R
    code = meas.kernel_kind << 2 | CHECK_Z | CHECK_R
    t = 10**15  # a large int: one object, its count checked
    ins = (x, P, z, b, t, FQ, spec, R)
    before = [sys.getrefcount(o) for o in ins]
    for call in (lambda: single.step(x, P, z, b, t), lambda: single.update(code, x, P, z, spec, R, t)):
        out = call()
        assert isinstance(out, Update) and out.state.t_ns is t
        refs = [weakref.ref(a) for a in (out.state.x, out.state.P, out.y, out.S)]
        del out
        gc.collect()
        assert all(r() is None for r in refs)
    p = single.predict(x, P, FQ, t, True)
    refs = [weakref.ref(a) for a in p[:2]]
    del p
    gc.collect()
    assert all(r() is None for r in refs)
    assert [sys.getrefcount(o) for o in ins] == before
    bad = z.copy()
    bad[0] = NAN
    badR = -np.asarray(R)

    def calls() -> None:
        single.step(x, P, bad, b, t)  # BAD_Z
        single.step(x, -P, z, b, t)  # S not positive definite: results allocated, then freed
        single.step(x, P, z, b, t)
        single.update(code, x, P, bad, spec, R, t)
        single.update(code, x, -P, z, spec, R, t)
        single.update(code, x, P, z, spec, badR, t)  # BAD_R
        single.update(code, x, P, z, spec, R, t)
        single.predict(x, P, FQ, t, True)
        single.predict(bad[:1].repeat(4), P, FQ, t, True)  # NONFINITE

    grown = traced_growth(calls, warm=200, n=10_000)
    assert grown < 10_000, grown
