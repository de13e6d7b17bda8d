"""Kernels and filter equivalences:
- update_arrays on a stack of N states equals update_single on each, and predict_arrays equals
  the per-state prediction;
- the UKF on a linear Gaussian model is exact, so it equals the KF (to 1e-9 relative);
- an IMM of two identical filters equals the single filter.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from fusion.core.imm import IMM
from fusion.core.kalman import KalmanFilter, predict_arrays, update_arrays, update_single
from fusion.core.measurement import CartesianPosition
from fusion.core.motion import ConstantAcceleration, ConstantVelocity
from fusion.core.ukf import SigmaPoints, UnscentedKalmanFilter
from fusion.scenarios import reference, run_reference


def _spd(rng: np.random.Generator, n: int, *lead: int) -> np.ndarray:
    A = rng.standard_normal((*lead, n, n))
    return A @ np.swapaxes(A, -1, -2) + 0.5 * np.eye(n)


SHAPES = ((4, 2), (6, 3), (5, 1), (3, 3))


@pytest.mark.parametrize("seed", (0, 1), ids=["seed0", "seed1"])
@pytest.mark.parametrize("nm", SHAPES, ids=[f"n{n}m{m}" for n, m in SHAPES])
def test_update_arrays_equals_update_single(nm: tuple[int, int], seed: int) -> None:
    n, m = nm
    N = 9
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((N, n))
    P = _spd(rng, n, N)
    y = rng.standard_normal((N, m))
    H = rng.standard_normal((N, m, n))
    R = _spd(rng, m, N)
    xs, Ps, Ss, nis, ll = update_arrays(x, P, y, H, R)
    assert xs.shape == (N, n) and Ps.shape == (N, n, n) and Ss.shape == (N, m, m)
    assert nis.shape == (N,) and ll.shape == (N,)
    for i in range(N):
        x1, P1, S1, nis1, ll1 = update_single(x[i], P[i], y[i], H[i], R[i])
        msg = f"seed={seed} i={i}"
        np.testing.assert_allclose(xs[i], x1, rtol=1e-11, atol=1e-12, err_msg=msg)
        np.testing.assert_allclose(Ps[i], P1, rtol=1e-11, atol=1e-12, err_msg=msg)
        np.testing.assert_allclose(Ss[i], S1, rtol=1e-13, err_msg=msg)
        assert nis[i] == pytest.approx(nis1, rel=1e-11), msg
        assert ll[i] == pytest.approx(ll1, rel=1e-11), msg
        # and both agree with the plain formulas
        S = H[i] @ P[i] @ H[i].T + R[i]
        K = P[i] @ H[i].T @ np.linalg.inv(S)
        np.testing.assert_allclose(x1, x[i] + K @ y[i], rtol=1e-9, atol=1e-10, err_msg=msg)
        assert nis1 == pytest.approx(y[i] @ np.linalg.solve(S, y[i]), rel=1e-9), msg
        _, logdet = np.linalg.slogdet(S)
        assert ll1 == pytest.approx(-0.5 * (nis1 + logdet + m * np.log(2 * np.pi)), rel=1e-9), msg


def test_update_arrays_shared_H_R_broadcast() -> None:
    rng = np.random.default_rng(4)
    N, n, m = 6, 4, 2
    x, P, y = rng.standard_normal((N, n)), _spd(rng, n, N), rng.standard_normal((N, m))
    H, R = rng.standard_normal((m, n)), _spd(rng, m)
    xs, Ps, *_ = update_arrays(x, P, y, H, R)
    for i in range(N):
        x1, P1, *_ = update_single(x[i], P[i], y[i], H, R)
        np.testing.assert_allclose(xs[i], x1, rtol=1e-11, atol=1e-12, err_msg=f"seed=4 i={i}")
        np.testing.assert_allclose(Ps[i], P1, rtol=1e-11, atol=1e-12, err_msg=f"seed=4 i={i}")


def test_predict_arrays_equals_stacked() -> None:
    rng = np.random.default_rng(12)
    m = ConstantAcceleration(ndim=2, q=0.3)
    N = 7
    dts = rng.uniform(0.0, 2.0, N)
    x = rng.standard_normal((N, m.ndim_state))
    P = _spd(rng, m.ndim_state, N)
    xs, Ps = predict_arrays(x, P, m.F(dts), m.Q_dt(dts))
    for i in range(N):
        F = m.F(float(dts[i]))
        np.testing.assert_allclose(xs[i], F @ x[i], rtol=1e-13, err_msg=f"seed=12 i={i}")
        np.testing.assert_allclose(Ps[i], F @ P[i] @ F.T + m.Q_dt(float(dts[i])), rtol=1e-12,
                                   err_msg=f"seed=12 i={i}")
        assert np.array_equal(Ps[i], Ps[i].T)


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


UKF_CASES = ("cv1d_a", "cv1d_c", "cv1d_d", "maneuver2d", "helix3d")
POINTS = {"default": SigmaPoints(), "alpha0.5_kappa1": SigmaPoints(alpha=0.5, beta=2.0, kappa=1.0)}


@pytest.mark.parametrize("points", list(POINTS), ids=list(POINTS))
@pytest.mark.parametrize("name", UKF_CASES, ids=list(UKF_CASES))
def test_ukf_equals_kf_on_linear_models(name: str, points: str) -> None:
    seed = 21
    ref = reference(name, seed=seed)
    kf = run_reference(ref)
    ukf = run_reference(ref, UnscentedKalmanFilter(ref.motion, points=POINTS[points]))
    msg = f"{name} seed={seed} points={points}"
    for k in range(ref.n_steps):
        ex, eP = _rel(ukf.x[k], kf.x[k]), _rel(ukf.P[k], kf.P[k])
        assert ex < 1e-9, f"{msg}: x at step {k}: {ex:.3g}"
        assert eP < 1e-9, f"{msg}: P at step {k}: {eP:.3g}"
    np.testing.assert_allclose(ukf.nis, kf.nis, rtol=1e-7, atol=1e-9, err_msg=msg)


IMM_CASES = ("cv1d_a", "maneuver2d")


@pytest.mark.parametrize("name", IMM_CASES, ids=list(IMM_CASES))
def test_imm_of_identical_models_equals_single_filter(name: str) -> None:
    seed = 5
    ref = reference(name, seed=seed)
    kf = KalmanFilter(ref.motion)
    imm = IMM([KalmanFilter(ref.motion), KalmanFilter(ref.motion)], rates=[[-1.0, 1.0], [3.0, -3.0]])
    s1 = kf.initial(ref.x0, ref.P0, t_ns=0)
    s2 = imm.initial(ref.x0, ref.P0, t_ns=0, mu=[0.2, 0.8])
    for k in range(ref.n_steps):
        t = int(ref.t_ns[k])
        u1 = kf.update(kf.predict(s1, t), ref.z[k], ref.meas)
        u2 = imm.update(imm.predict(s2, t), ref.z[k], ref.meas)
        s1, s2 = u1.state, u2.state
        msg = f"{name} seed={seed} step {k}"
        assert _rel(s2.x, s1.x) < 1e-9, msg
        assert _rel(s2.P, s1.P) < 1e-9, msg
        assert u2.nis == pytest.approx(u1.nis, rel=1e-9, abs=1e-12), msg
        assert u2.log_likelihood == pytest.approx(u1.log_likelihood, rel=1e-9), msg
        # identical likelihoods: mode probabilities just follow the Markov chain
        assert s2.t_ns == t


def test_imm_mode_probabilities_follow_markov_chain_when_models_identical() -> None:
    ref = reference("cv1d_a", seed=5)
    rates = np.array([[-1.0, 1.0], [3.0, -3.0]])
    imm = IMM([KalmanFilter(ref.motion), KalmanFilter(ref.motion)], rates=rates)
    st = imm.initial(ref.x0, ref.P0, t_ns=0, mu=[0.2, 0.8])
    mu = np.array([0.2, 0.8])
    for k in range(10):
        st = imm.update(imm.predict(st, int(ref.t_ns[k])), ref.z[k], ref.meas).state
        mu = mu @ expm(rates * ref.dt_s)
        np.testing.assert_allclose(st.mu, mu, rtol=1e-12, err_msg=f"seed=5 step {k}")


def test_imm_combine_is_moment_matching() -> None:
    """Two filters with different Q: the IMM's (x, P) is the mixture's mean and covariance."""
    rng = np.random.default_rng(9)
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.01, 0.01])
    imm = IMM([KalmanFilter(ConstantVelocity(ndim=2, q=0.01)),
               KalmanFilter(ConstantVelocity(ndim=2, q=1.0))], rates=[[-0.5, 0.5], [0.5, -0.5]])
    st = imm.initial(np.zeros(4), np.eye(4), t_ns=0)
    for k in range(20):
        st = imm.update(imm.predict(st, (k + 1) * 100_000_000), rng.standard_normal(2), meas).state
    xs = np.stack([c.x for c in st.components])
    x = st.mu @ xs
    pairs = zip(st.mu, st.components, strict=True)
    P = sum(m * (c.P + np.outer(c.x - x, c.x - x)) for m, c in pairs)
    np.testing.assert_allclose(st.x, x, rtol=1e-12, atol=1e-14, err_msg="seed=9")
    np.testing.assert_allclose(st.P, P, rtol=1e-12, atol=1e-14, err_msg="seed=9")
    assert st.mu.sum() == pytest.approx(1.0, abs=1e-12)
