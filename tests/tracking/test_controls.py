"""Known control inputs: held between their times, applied through B, folded in exactly when late
(issue #12, item 1)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import CartesianSensorConfig, ControlConfig, LifecycleConfig, MotionConfig, TrackerConfig
from fusion.core.gaussian import GaussianState
from fusion.core.kalman import KalmanFilter
from fusion.core.motion import ConstantVelocity
from fusion.scenarios import reference, run_reference
from fusion.tracking.controls import InputTimeline
from fusion.tracking.detection import ControlInput, Detection, Reason
from fusion.tracking.tracker import Tracker

S = 1_000_000_000


def test_offset_equals_predicting_with_each_held_input() -> None:
    """Delta over [t0, t1) with inputs changing inside equals a chain of KF predictions, each
    with the input in force, minus the prediction without input."""
    cv = ConstantVelocity(ndim=2, q=0.5, with_control=True)
    kf = KalmanFilter(cv)
    tl = InputTimeline(cv, 2)
    changes = [(int(0.3 * S), np.array([1.0, -2.0])), (int(1.1 * S), np.array([0.0, 0.5])),
               (int(2.0 * S), np.array([-1.0, 0.0]))]
    for k, (t, u) in enumerate(changes):
        tl.add(t, k, u)
    x0 = GaussianState(np.array([1.0, 2.0, -3.0, 0.5]), np.eye(4), int(0.5 * S))
    t1 = int(2.4 * S)
    st, t, u = x0, x0.t_ns, tl.at(x0.t_ns)
    for tc, uc in changes[1:] + [(t1, None)]:
        st = kf.predict(st, tc, u=u)
        t, u = tc, uc
    plain = kf.predict(x0, t1)
    np.testing.assert_allclose(plain.x + tl.offset(x0.t_ns, t1), st.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(tl.at(int(0.2 * S)), np.zeros(2))  # before the first input: u = 0
    assert tl.offset(0, int(0.3 * S)) is None  # nothing acts before the first input


def _cv1d_d_tracker() -> Tracker:
    ref = reference("cv1d_d", seed=0)
    return Tracker(TrackerConfig(
        sensors=[CartesianSensorConfig(id="pos", std_m=[1.0])], control=ControlConfig(source_id="car"),
        motion=MotionConfig(model="cv", ndim=1, accel_psd_m2s3=ref.motion.q**2),  # type: ignore[attr-defined]
        lifecycle=LifecycleConfig(confirm_m=1, confirm_n=1)))


def _stream() -> list[Detection | ControlInput]:
    """cv1d_d: u[k] drives the step that ends at t[k]: in force from t[k-1]."""
    ref = reference("cv1d_d", seed=0)
    out: list[Detection | ControlInput] = []
    for k in range(ref.n_steps):
        out.append(ControlInput.of("car", 0 if k == 0 else int(ref.t_ns[k - 1]), k, ref.u[k]))  # type: ignore[index]
        out.append(Detection.of("pos", int(ref.t_ns[k]), k, ref.z[k]))
    return out


def _run(order: list[Detection | ControlInput], batch: int = 1) -> dict[int, np.ndarray]:
    tr = _cv1d_d_tracker()
    est: dict[int, np.ndarray] = {}
    for i in range(0, len(order), batch):
        r = tr.process(order[i:i + batch])
        assert not r.refused, r.refused
        for e in r.estimates:
            if e.status != "retracted":
                est[e.t_ns] = np.concatenate([e.x, e.P.ravel()])
    assert tr.counts.inputs == sum(isinstance(x, ControlInput) for x in order)
    return est


def test_cv1d_d_with_its_input_matches_the_reference_filter() -> None:
    ref = reference("cv1d_d", seed=0)
    est = _run(_stream())
    x = np.array([est[int(t)][:2] for t in ref.t_ns])
    rmse = float(np.sqrt(np.mean((x[:, 0] - ref.truth[:, 0]) ** 2)))
    off = run_reference(ref)
    rmse_off = float(np.sqrt(np.mean((off.x[:, 0] - ref.truth[:, 0]) ** 2)))
    assert abs(rmse - rmse_off) < 0.02 * rmse_off, (rmse, rmse_off)
    # Without the input the same filter lags the accelerating car: its velocity is worse. (The
    # document's process noise is as large as the input, so position suffers less.)
    tr = _cv1d_d_tracker()
    blind = {}
    for d in _stream():
        if isinstance(d, Detection):
            blind.update({e.t_ns: e.x for e in tr.process([d]).estimates})
    v_blind = np.array([blind[int(t)][1] for t in ref.t_ns]) - ref.truth[:, 1]
    v_input = x[:, 1] - ref.truth[:, 1]
    assert np.sqrt(np.mean(v_blind**2)) > 1.1 * np.sqrt(np.mean(v_input**2))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_late_inputs_fold_in_exactly(seed: int) -> None:
    """Inputs delivered up to 1 s late, measurements in order: the same estimates, bit for bit."""
    stream = _stream()
    rng = np.random.default_rng(seed)
    delay = [int(rng.integers(0, S)) if isinstance(x, ControlInput) else 0 for x in stream]
    order = [stream[i] for i in sorted(range(len(stream)), key=lambda i: (stream[i].t_ns + delay[i], i))]
    assert order != stream
    ref_est, got = _run(stream), _run(order, batch=3)
    assert got.keys() == ref_est.keys()
    for t in ref_est:
        np.testing.assert_array_equal(got[t], ref_est[t])


def test_bad_inputs_are_refused_with_their_reason() -> None:
    tr = _cv1d_d_tracker()
    tr.process([Detection.of("pos", 0, 0, [0.0])])
    cases = [(ControlInput.of("brake", S // 10, 0, [1.0]), Reason.UNKNOWN_SENSOR),
             (ControlInput.of("car", S // 10, 1, [1.0, 2.0]), Reason.INVALID),
             (ControlInput.of("car", S // 10, 2, [np.nan]), Reason.INVALID)]
    for c, reason in cases:
        (r,) = tr.process([c]).refused
        assert r.reason == reason
    assert not tr.process([ControlInput.of("car", S // 10, 3, [1.0])]).refused
    (r,) = tr.process([ControlInput.of("car", S // 10, 3, [1.0])]).refused
    assert r.reason == Reason.DUPLICATE
