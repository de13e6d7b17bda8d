"""Motion models: Q equals the docstrings' closed forms, F is a semigroup, batched F and Q
equal the stacked scalar results, and the coordinated turn tends to constant velocity."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import block_diag

from fusion.core.motion import ConstantAcceleration, ConstantVelocity, CoordinatedTurn

DTS = (0.0, 1e-3, 0.1, 1.0, 2.5)
NDIMS = (1, 2, 3)


def _cv_closed(q: float, dt: float, d: int) -> tuple[np.ndarray, np.ndarray]:
    F = np.array([[1, dt], [0, 1]])
    Q = q**2 * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    return block_diag(*[F] * d), block_diag(*[Q] * d)


def _ca_closed(q: float, dt: float, d: int) -> tuple[np.ndarray, np.ndarray]:
    F = np.array([[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
    Q = q**2 * np.array([
        [dt**5 / 20, dt**4 / 8, dt**3 / 6],
        [dt**4 / 8, dt**3 / 3, dt**2 / 2],
        [dt**3 / 6, dt**2 / 2, dt],
    ])
    return block_diag(*[F] * d), block_diag(*[Q] * d)


KINDS = {"cv": (ConstantVelocity, _cv_closed), "ca": (ConstantAcceleration, _ca_closed)}


@pytest.mark.parametrize("dt", DTS, ids=[f"dt{d}" for d in DTS])
@pytest.mark.parametrize("ndim", NDIMS, ids=[f"{d}d" for d in NDIMS])
@pytest.mark.parametrize("kind", list(KINDS), ids=list(KINDS))
def test_F_and_Q_match_docstring(kind: str, ndim: int, dt: float) -> None:
    cls, closed = KINDS[kind]
    q = 0.7
    m = cls(ndim=ndim, q=q)
    F, Q = closed(q, dt, ndim)
    x = np.arange(1.0, m.ndim_state + 1)
    np.testing.assert_allclose(m.F(dt), F, rtol=1e-14, atol=0)
    np.testing.assert_allclose(m.Q(x, dt), Q, rtol=1e-13, atol=1e-300)
    np.testing.assert_allclose(m.jacobian(x, dt), F, rtol=1e-14, atol=0)
    np.testing.assert_allclose(m.f(x, dt), F @ x, rtol=1e-14)
    assert m.position_indices == tuple(m.order * i for i in range(ndim))
    assert m.velocity_indices == tuple(m.order * i + 1 for i in range(ndim))


def test_cv_control_matrix() -> None:
    m = ConstantVelocity(ndim=2, q=1.0, with_control=True)
    dt = 0.3
    np.testing.assert_allclose(m.control(dt), block_diag([[dt**2 / 2], [dt]], [[dt**2 / 2], [dt]]))
    assert ConstantVelocity(ndim=2, q=1.0).control(dt) is None


PAIRS = ((0.1, 0.2), (1.0, 2.5), (0.0, 0.7), (1e-3, 3.0))


@pytest.mark.parametrize("pair", PAIRS, ids=[f"{a}+{b}" for a, b in PAIRS])
@pytest.mark.parametrize("kind", list(KINDS), ids=list(KINDS))
def test_F_semigroup_and_Q_additivity(kind: str, pair: tuple[float, float]) -> None:
    """F(a) F(b) = F(a + b); the exact discretisation composes: Q(a+b) = F(b) Q(a) F(b)' + Q(b)."""
    a, b = pair
    m = KINDS[kind][0](ndim=2, q=1.3)
    Fa, Fb, Fab = m.F(a).copy(), m.F(b).copy(), m.F(a + b).copy()
    Qa, Qb, Qab = m.Q_dt(a).copy(), m.Q_dt(b).copy(), m.Q_dt(a + b).copy()
    np.testing.assert_allclose(Fa @ Fb, Fab, rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(Fb @ Qa @ Fb.T + Qb, Qab, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("kind", list(KINDS), ids=list(KINDS))
def test_batched_F_Q_equal_stacked_scalars(kind: str) -> None:
    rng = np.random.default_rng(17)
    m = KINDS[kind][0](ndim=3, q=0.4)
    dts = np.concatenate([[0.0], rng.uniform(0.0, 3.0, 9)])
    Fb, Qb = m.F(dts), m.Q_dt(dts)
    assert Fb.shape == (10, m.ndim_state, m.ndim_state) and Qb.shape == Fb.shape
    X = rng.standard_normal((10, m.ndim_state))
    fb = m.f(X, dts)
    for i, dt in enumerate(dts):
        msg = f"seed=17 dt={dt}"
        np.testing.assert_allclose(Fb[i], m.F(float(dt)), rtol=1e-15, err_msg=msg)
        np.testing.assert_allclose(Qb[i], m.Q_dt(float(dt)), rtol=1e-14, atol=1e-300, err_msg=msg)
        np.testing.assert_allclose(fb[i], m.f(X[i], float(dt)), rtol=1e-14, err_msg=msg)
    # 2-d leading shape
    np.testing.assert_allclose(m.Q_dt(dts.reshape(2, 5)), Qb.reshape(2, 5, *Qb.shape[1:]))


def test_scalar_cache_is_not_corrupted_by_interleaving() -> None:
    """F and Q cache the last scalar dt; interleaved calls still give the right matrices."""
    m = ConstantVelocity(ndim=1, q=1.0)
    F1 = m.F(1.0).copy()
    Q2 = m.Q_dt(2.0).copy()
    np.testing.assert_allclose(m.F(1.0), F1)
    np.testing.assert_allclose(m.Q_dt(2.0), Q2)
    np.testing.assert_allclose(m.F(2.0), [[1, 2], [0, 1]])
    np.testing.assert_allclose(m.Q_dt(np.float64(1.0)), [[1 / 3, 1 / 2], [1 / 2, 1]])


CT = CoordinatedTurn(q_accel=0.5, q_turn=0.02)
OMEGAS = (1e-2, 1e-4, 1e-6, 1e-8, 0.0, -1e-8, -1e-5)


@pytest.mark.parametrize("omega", OMEGAS, ids=[f"omega{w:g}" for w in OMEGAS])
def test_coordinated_turn_tends_to_cv(omega: float) -> None:
    cv = ConstantVelocity(ndim=2, q=0.5)
    dt = 2.0
    x4 = np.array([100.0, 12.0, -30.0, 7.0])
    x = np.append(x4, omega)
    out = CT.f(x, dt)
    cv_out = cv.f(x4, dt)
    # |f_CT - f_CV| = O(omega dt * |v| dt): the turn displaces by about omega dt^2 |v| / 2
    bound = 2.0 * abs(omega) * dt * np.hypot(12.0, 7.0) * dt + 1e-12
    assert np.max(np.abs(out[:4] - cv_out)) <= bound, f"omega={omega}: {out[:4]} vs {cv_out}"
    assert out[4] == omega
    J = CT.jacobian(x, dt)
    np.testing.assert_allclose(J[:4, :4], cv.F(dt), atol=bound + 1e-15)
    np.testing.assert_allclose(CT.Q(x, dt)[:4, :4], cv.Q_dt(dt), rtol=1e-14)
    assert CT.Q(x, dt)[4, 4] == pytest.approx(0.02**2 * dt)
    if omega == 0.0:
        np.testing.assert_array_equal(out[:4], cv_out)


def test_coordinated_turn_exact_rotation() -> None:
    """A quarter turn: speed preserved, velocity rotated by omega dt, centre of the circle fixed."""
    w, dt, v = 0.5, np.pi, 10.0  # omega dt = pi/2
    x = np.array([0.0, v, 0.0, 0.0, w])
    out = CT.f(x, dt)
    r = v / w
    np.testing.assert_allclose(out, [r, 0.0, r, v, w], atol=1e-12)


def _ct_stack(n: int, seed: int) -> tuple[CoordinatedTurn, np.ndarray, np.ndarray]:
    """A CT model and a stack of n states (omega 0, 1e-8 and ordinary turn rates: the series for
    tiny |omega dt| and the closed form) with steps dt (n,) from 1 ms to 2.5 s."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 5)) * [100.0, 10.0, 100.0, 10.0, 0.1]
    x[::3, 4] = 0.0
    x[1::4, 4] = 1e-8
    return CoordinatedTurn(q_accel=0.05, q_turn=0.03), x, rng.choice([1e-3, 0.05, 0.1, 2.5], n)


@pytest.mark.parametrize("n", [1, 7, 300], ids=lambda n: f"N{n}")
def test_coordinated_turn_compiled_stack_equals_numpy_bit_for_bit(n: int) -> None:
    """A stack x (N, 5) with dt (N,) takes fusion.core.compiled_motion's loops; they give the
    numpy formulation's numbers (here through a (1, N, 5) stack, which stays on numpy) exactly,
    the series for tiny |omega dt| included (omega 0, 1e-8, and ordinary turn rates)."""
    seed = 11 + n
    m, x, dt = _ct_stack(n, seed)
    for got, ref in ((m.f(x, dt), m.f(x[None], dt[None])[0]), (m.jacobian(x, dt), m.jacobian(x[None], dt[None])[0])):
        assert got.shape == ref.shape, f"seed {seed}"
        assert np.array_equal(got, ref), f"seed {seed}: max diff {np.abs(got - ref).max()}"


@pytest.mark.parametrize("n", [1, 7, 300], ids=lambda n: f"N{n}")
def test_f_and_jacobian_equals_the_two_calls_bit_for_bit(n: int) -> None:
    """f_and_jacobian (what the stacked IMM's predict calls for a nonlinear mode) gives f's and
    jacobian's arrays exactly: CoordinatedTurn's from one set of terms, on stacks (the compiled
    loops, the series for tiny |omega dt| included) and on other shapes; any other model by the
    base class's two calls."""
    seed = 23 + n
    m, x, dt = _ct_stack(n, seed)
    rng = np.random.default_rng(seed + 1)
    cases = [(m, x, dt), (m, x[None], dt[None]), (m, x[0], float(dt[0])),
             (ConstantAcceleration(ndim=2, q=0.3), rng.normal(size=(n, 6)), dt)]
    for model, xi, di in cases:
        f, J = model.f_and_jacobian(xi, di)
        assert f.shape == model.f(xi, di).shape and np.array_equal(f, model.f(xi, di)), f"seed {seed}: {model}"
        assert np.array_equal(J, model.jacobian(xi, di)), f"seed {seed}: {model}"
