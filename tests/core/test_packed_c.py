"""The C call of the planned step (fusion.core._packed_step) against numba's twin, and its edges.

- the install built it wherever a C compiler is on the PATH (CI's machine has one; without one
  the package still installs and step() runs the twin, which the rest of the suite then tests);
- over random states, time steps, z and every model of test_packed_step (hypothesis), validated
  or not, the C call returns the same bits and the same status as numba's step_packed, including
  NaN and inf in z or x and an S that is not positive definite;
- strided and Fortran-ordered inputs are read right; what it does not take (a byte-swapped or
  unaligned array, z not a float64 vector, a non-int time) it hands back as NOT_TAKEN, and the
  filter's step() then gives the bits of predict then update all the same;
- a blob too short for the sizes it names is SHAPE, not a read past its end;
- nothing is leaked or kept: the results are freed with the Update, the inputs' reference counts
  are unchanged, and many failing calls allocate nothing that stays.
"""

from __future__ import annotations

import gc
import shutil
import sys
import sysconfig
import tracemalloc
import weakref

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.core import packed_step
from fusion.core.gaussian import GaussianState, Update
from fusion.core.step_plan import blob, make_plan
from fusion.core.transitions import TransitionCache
from tests.core.test_packed_step import BUILT, MODELS, _filter, _motion, _same, _start

needs_c = pytest.mark.skipif(not packed_step.COMPILED, reason="the C extension was not built")
NAN, INF = float("nan"), float("inf")


def _c_compiler() -> str | None:
    cc = (sysconfig.get_config_var("CC") or "cc").split()[0]
    return shutil.which(cc)


@pytest.mark.skipif(not packed_step.COMPILED and _c_compiler() is None,
                    reason="no C compiler here: step() runs numba's twin")
def test_the_install_built_the_c_extension() -> None:
    """Where there is a C compiler, pip install must have built the extension (setup.py makes it
    optional, so a failed build would otherwise pass unseen)."""
    assert packed_step.COMPILED, (f"fusion.core._packed_step is missing though {_c_compiler()} is here: "
                                  "see the build's output of pip install -v -e .")
    assert packed_step.step is not packed_step.step_numba


def _blob(name: str, check: bool, dt_ns: int) -> np.ndarray:
    meas = BUILT[name]
    return blob(make_plan(TransitionCache(_motion(meas)), meas, check=check), dt_ns)


def _both(x: np.ndarray, P: np.ndarray, z: np.ndarray, b: np.ndarray, t: int) -> tuple[object, object]:
    c = packed_step.step(x, P, z, b, t)
    nb = packed_step.step_numba(x, P, z, b.copy(), t)  # its own scratch: the same blob contents
    return c, nb


def _agree(c: object, nb: object) -> None:
    if isinstance(nb, int):
        assert c == nb and type(c) is int
        return
    assert type(c) is Update and type(c.state) is GaussianState
    _same(c, nb)  # type: ignore[arg-type]


@needs_c
@settings(max_examples=80, deadline=None)
@given(name=st.sampled_from(sorted(MODELS)), check=st.booleans(), seed=st.integers(0, 2**32 - 1),
       dt_ns=st.integers(0, 5_000_000_000), t=st.integers(-(2**62), 2**62),
       spoil=st.sampled_from(["none", "z_nan", "z_inf", "x_nan", "P_neg", "z_huge"]))
def test_c_gives_the_bits_and_status_of_numba(name: str, check: bool, seed: int, dt_ns: int, t: int,
                                              spoil: str) -> None:
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
    c, nb = _both(x, P, z, _blob(name, check, dt_ns), t)
    _agree(c, nb)
    if not isinstance(c, int):
        assert c.state.t_ns == t


@needs_c
@pytest.mark.parametrize("name", sorted(MODELS))
def test_strided_and_fortran_inputs_read_right(name: str) -> None:
    rng = np.random.default_rng(11)
    meas = BUILT[name]
    s = _start(meas.ndim_state, rng)
    n, m = meas.ndim_state, meas.ndim_meas
    z = meas.h(s.x) + 0.3
    b = _blob(name, True, 250_000_000)
    ref = packed_step.step(s.x, s.P, z, b, 7)
    wide = np.zeros((3 * n, 2))
    wide[::3, 1] = s.x  # x as a view with a stride of 48 bytes
    zs = np.zeros(2 * m)
    zs[::2] = z
    got = packed_step.step(wide[::3, 1], np.asfortranarray(s.P), zs[::2], b, 7)
    assert isinstance(got, Update)
    _same(got, ref)  # type: ignore[arg-type]
    _same(packed_step.step(s.x, s.P.T.copy().T, z[::-1][::-1], b, 7), ref)  # type: ignore[arg-type]


def _unaligned(a: np.ndarray) -> np.ndarray:
    raw = np.zeros(a.nbytes + 1, dtype=np.uint8)
    out = raw[1:].view(a.dtype).reshape(a.shape)
    out[...] = a
    assert not out.flags.aligned
    return out


@needs_c
def test_what_it_does_not_take_is_not_taken_and_step_still_agrees() -> None:
    rng = np.random.default_rng(13)
    meas = BUILT["radar"]
    f = _filter(meas, True)
    s = _start(4, rng)
    t = s.t_ns + 100_000_000
    z = meas.h(f.predict(s, t).x) + np.array([1.0, 1e-3])
    f.step(s, t, z, meas)  # the plan exists
    b = f._plans[meas].blobs[100_000_000]  # the filter's own blob (white-box: handed to the call)
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
        assert packed_step.step(x, P, zz, b, tt) == packed_step.NOT_TAKEN, what
    two = f.update(f.predict(s, t), z, meas)
    _same(f.step(GaussianState(s.x, _unaligned(s.P), s.t_ns), t, z, meas), two)  # through numba's twin
    _same(f.step(s, np.int64(t), z, meas), two)
    _same(f.step(s, t, list(z), meas), two)


@needs_c
def test_a_blob_too_short_is_shape_not_a_read_past_its_end() -> None:
    b = _blob("cart_2d", True, 100_000_000)
    x, P, z = np.zeros(4), np.eye(4), np.zeros(2)
    assert isinstance(packed_step.step(x, P, z, b, 0), Update)
    for cut in (0, 3, 4, 20, len(b) - 1):
        assert packed_step.step(x, P, z, b[:cut].copy(), 0) == 2  # compiled_step.SHAPE
    assert packed_step.step(np.zeros(6), np.eye(6), z, b, 0) == 2
    assert packed_step.step(x, P, np.zeros(3), b, 0) == 2
    with pytest.raises(TypeError, match="5 arguments"):
        packed_step.step(x, P, z, b)
    from fusion.core import _packed_step

    with pytest.raises(TypeError):
        _packed_step.bind(int, Update)


@needs_c
def test_nothing_is_leaked_or_kept() -> None:
    b = _blob("radar_rr", True, 100_000_000)
    rng = np.random.default_rng(17)
    s = _start(4, rng)
    x, P = s.x, s.P
    z = BUILT["radar_rr"].h(x) + 0.1
    t = 10**15  # a large int: one object, its count checked
    before = [sys.getrefcount(o) for o in (x, P, z, b, t)]
    up = packed_step.step(x, P, z, b, t)
    assert isinstance(up, Update) and up.state.t_ns is t
    refs = [weakref.ref(a) for a in (up.state.x, up.state.P, up.y, up.S)]
    del up
    gc.collect()
    assert all(r() is None for r in refs)
    assert [sys.getrefcount(o) for o in (x, P, z, b, t)] == before
    bad = z.copy()
    bad[0] = NAN
    gc.collect()
    tracemalloc.start()
    try:
        for _ in range(200):
            packed_step.step(x, P, bad, b, t)
            packed_step.step(x, -P, z, b, t)
            packed_step.step(x, P, z, b, t)
        gc.collect()
        base, _ = tracemalloc.get_traced_memory()
        for _ in range(20_000):
            packed_step.step(x, P, bad, b, t)  # BAD_Z
            packed_step.step(x, -P, z, b, t)  # S not positive definite: results allocated, then freed
            packed_step.step(x, P, z, b, t)
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - base
    finally:
        tracemalloc.stop()
    assert grown < 10_000, grown
