"""An estimate's review rows (fusion.tracking.results.Review: prior, innovation, its covariance,
the Jacobian, the measured position) are those of the update that made it, also where a scan
mixes measurement dimensions (radar returns with and without range rate: one Review block per
dimension, the estimates of each in the scan's track order), and a scan's estimates share their
blocks."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fusion.config import LifecycleConfig, MotionConfig, RadarSensorConfig, TrackerConfig, load_service_config
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker

RADAR = np.array([0.0, -2000.0])


def _radar(k: int, targets: np.ndarray, v: np.ndarray, rng: np.random.Generator, *, rate_every: int) -> list:
    """Returns of `targets` (positions at scan k, velocities v): every `rate_every`-th one (by
    target and scan) with range rate, the others without."""
    out = []
    for i, (p, vi) in enumerate(zip(targets, v, strict=True)):
        d = p - RADAR
        r = float(np.hypot(*d))
        z = [r + rng.normal(0.0, 1.0), float(np.arctan2(d[1], d[0])) + rng.normal(0.0, 1e-3)]
        if (i + k) % rate_every == 0:
            z.append(float(d @ vi) / r + rng.normal(0.0, 0.5))
        out.append(Detection.of("r", k * 100_000_000, k * 100 + i, z))
    return out


def test_review_rows_are_the_update_of_each_estimate_with_mixed_dimensions() -> None:
    cfg = TrackerConfig(sensors=[RadarSensorConfig(id="r", position_m=list(RADAR), range_std_m=1.0,
                                                   bearing_std_rad=1e-3, range_rate_std_mps=0.5)],
                        motion=MotionConfig(accel_psd_m2s3=0.5), lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3))
    tr = Tracker(cfg)
    rng = np.random.default_rng(4)
    start = np.stack([np.linspace(-600.0, 600.0, 7), np.full(7, 300.0)], axis=1)
    v = np.stack([np.full(7, 8.0), np.linspace(-5.0, 5.0, 7)], axis=1)
    mixed_scans = shared = checked = 0
    for k in range(30):
        dets = _radar(k, start + 0.1 * k * v, v, rng, rate_every=3)
        by_seq = {d.seq: d for d in dets}
        E = [e for e in tr.process(dets).estimates if e.status != "retracted"]
        updated = [e for e in E if e.nis is not None]
        blocks = {id(e.review) for e in updated}
        dims = {by_seq[e.seq].z.size for e in updated}
        assert len(blocks) == len(dims)  # one block per measurement dimension, shared by its estimates
        mixed_scans += len(dims) > 1
        shared += len(updated) > len(blocks)
        for e in E:
            # its posterior is its row of its block (the same memory where the scan has one dimension)
            assert e.x.tobytes() == e.review.X[e.row].tobytes() and e.P.tobytes() == e.review.P[e.row].tobytes()
            assert np.shares_memory(e.x, e.review.X) == (len(dims) == 1 or e.nis is None)
            z = by_seq[e.seq].z  # range, bearing (, range rate): the measured world position
            assert np.allclose(e.meas_pos[:2], RADAR + z[0] * np.array([np.cos(z[1]), np.sin(z[1])]), atol=1e-9)
            if e.nis is None:  # a birth: no prior, no innovation
                assert e.y is None and e.S is None and e.H is None and e.prior_x is None and e.prior_P is None
                continue
            assert e.y.shape == (z.size,) and e.S.shape == (z.size, z.size) and e.H.shape == (z.size, 4)
            # the EKF update they made: K = P- H' S^-1, x = x- + K y, P = (I - K H) P- (Joseph form aside)
            K = e.prior_P @ e.H.T @ np.linalg.inv(e.S)
            assert np.allclose(e.x, e.prior_x + K @ e.y, rtol=1e-9, atol=1e-6)
            assert np.allclose(e.P, (np.eye(4) - K @ e.H) @ e.prior_P, rtol=1e-6, atol=1e-6)
            assert np.isclose(e.nis, e.y @ np.linalg.solve(e.S, e.y), rtol=1e-9)
            checked += 1
    assert mixed_scans >= 10 and shared >= 10 and checked >= 100, (mixed_scans, shared, checked)


def test_an_imms_blocks_hold_its_mode_probabilities() -> None:
    """With the shipped IMM (configs/service.toml's motion: CV and CT), each estimate's mode
    probabilities are its row of its block's MU (Review.MU), for updates of either measurement
    dimension and for births: what the recording reads block by block (fusion.io.view_rows)."""
    motion = load_service_config(Path(__file__).parents[2] / "configs" / "service.toml").tracker.motion
    assert motion.model == "imm"
    cfg = TrackerConfig(sensors=[RadarSensorConfig(id="r", position_m=list(RADAR), range_std_m=1.0,
                                                   bearing_std_rad=1e-3, range_rate_std_mps=0.5)],
                        motion=motion, lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3))
    tr = Tracker(cfg)
    rng = np.random.default_rng(5)
    start = np.stack([np.linspace(-600.0, 600.0, 7), np.full(7, 300.0)], axis=1)
    v = np.stack([np.full(7, 8.0), np.linspace(-5.0, 5.0, 7)], axis=1)
    births = updates = 0
    for k in range(20):
        for e in tr.process(_radar(k, start + 0.1 * k * v, v, rng, rate_every=3)).estimates:
            if e.status == "retracted":
                continue
            assert e.mode_probabilities is not None and e.review.MU is not None
            assert e.review.MU.shape == (len(e.review.X), 2)
            assert e.review.MU[e.row].tobytes() == e.mode_probabilities.tobytes()
            births += e.nis is None
            updates += e.nis is not None
    assert births >= 7 and updates >= 100, (births, updates)
