"""Other filter configurations inside the tracker: the IMM of constant velocity and coordinated
turn (estimates carry mode probabilities) and the UKF (on the radar's nonlinear measurements)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import ModeConfig, MotionConfig
from fusion.core.metrics import rmse
from tests.tracking.helpers import Consumer, make_tracker, positions_at
from tests.tracking.streams import NS_PER_S, Sensor, constant_velocity, detect, in_order, scans

CART = Sensor("cart", "cartesian", period_s=0.5, std_m=2.0)
RADAR = Sensor("radar", "radar", period_s=0.5, offset_s=0.25, range_std_m=2.0, bearing_std_rad=0.003,
               position_m=(-600.0, -400.0))
MANOEUVRE = (0, 15.0, 21.0, 0.25)  # target 0 turns at 0.25 rad/s from 15 s to 21 s (~1.5 rad, 3-4 m/s^2)


IMM_CV_CT = MotionConfig(model="imm", modes=[
    ModeConfig(model="cv", accel_psd_m2s3=0.25, sojourn_s=20.0),
    ModeConfig(model="ct", accel_psd_m2s3=0.25, turn_psd_rad2s3=0.01, sojourn_s=5.0),
])


def manoeuvring_run(motion: MotionConfig, seed: int, sensors=(CART, RADAR)):
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=2, duration_s=35.0, rng=rng, speed_mps=(12.0, 15.0), spread_m=200.0,
                              manoeuvre=MANOEUVRE)
    dets = in_order(*(detect(truth, s, rng=rng, pd=0.95, clutter_mean=0.5, region_m=(-500, 500, -500, 500))
                      for s in sensors))
    tr = make_tracker(list(sensors), motion=motion)
    consumer = Consumer()
    est, true = [], []
    for batch in scans(dets):
        consumer.take(tr.process([d.det for d in batch]))
        t = batch[0].det.t_ns
        if t >= 3 * NS_PER_S:
            _, pos = positions_at(tr, t)
            tp = truth.positions(t)
            D = np.linalg.norm(tp[:, None] - pos[None], axis=-1)
            assert D.shape[1] >= 2 and (D.min(axis=1) < 25.0).all(), f"seed={seed} t={t}: {D.min(axis=1)}"
            est.append(pos[D.argmin(axis=1)])
            true.append(tp)
    return tr, consumer, rmse(np.concatenate(est), np.concatenate(true))


@pytest.mark.parametrize("seed", [61, 62], ids=["seed61", "seed62"])
def test_imm_tracks_through_a_manoeuvre_with_mode_probabilities(seed: int) -> None:
    tr, consumer, err = manoeuvring_run(IMM_CV_CT, seed)
    assert len(tr.confirmed()) >= 2  # (seed 62: target 0's track is replaced once in the turn)
    for e in consumer.latest.values():
        mu = e.mode_probabilities
        assert mu is not None and mu.shape == (2,), e
        assert np.all(mu >= 0.0) and mu.sum() == pytest.approx(1.0, abs=1e-9)
    # The high-noise mode takes over in the turn and gives way afterwards (target 0's track).
    assert all(t.state.mu.shape == (2,) for t in tr.confirmed())
    by_track: dict[int, list[tuple[int, float]]] = {}
    for (tid, t_ns, _), e in consumer.latest.items():
        by_track.setdefault(tid, []).append((t_ns, float(e.mode_probabilities[1])))
    def mean_high(tid: int, a: float, b: float) -> float:
        return float(np.mean([p for t, p in by_track[tid] if a * NS_PER_S <= t < b * NS_PER_S]))
    turning = max((tid for tid in by_track if len(by_track[tid]) > 100),
                  key=lambda tid: mean_high(tid, 15.5, 21.0))
    turn, before = mean_high(turning, 15.5, 21.0), mean_high(turning, 5.0, 14.0)
    msg = f"seed={seed}: P(high) {turn:.2f} in the turn, {before:.2f} before"
    assert turn > 1.5 * before and turn > before + 0.1, msg
    assert err < 5.0, f"seed={seed}: position RMSE {err:.2f} m"


@pytest.mark.parametrize("seed", [71, 72], ids=["seed71", "seed72"])
def test_ukf_tracker_matches_the_ekf_on_radar(seed: int) -> None:
    motion = dict(model="cv", accel_psd_m2s3=1.0)
    _, ukf_consumer, ukf_err = manoeuvring_run(MotionConfig(filter="ukf", **motion), seed, sensors=(RADAR,))
    _, _, ekf_err = manoeuvring_run(MotionConfig(filter="ekf", **motion), seed, sensors=(RADAR,))
    assert all(e.mode_probabilities is None for e in ukf_consumer.latest.values())
    assert ukf_err < 6.0 and abs(ukf_err - ekf_err) < 0.2 * ekf_err, f"seed={seed}: UKF {ukf_err:.2f} EKF {ekf_err:.2f}"
    for e in ukf_consumer.latest.values():
        assert np.allclose(e.P, e.P.T) and np.all(np.linalg.eigvalsh(e.P) > 0)
