"""The batched and per-pair gates agree to 1e-12 on every model both serve (CV, CA, CT, IMMs of
them, UKFs over CV and CT), inside the tracker."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fusion.config import ModeConfig, MotionConfig, TrackerConfig
from fusion.tracking.batched_gating import BatchedGate, BatchedIMMGate, BatchedUKFGate
from fusion.tracking.gating import PerPairGate
from fusion.tracking.tracker import Tracker
from tests.tracking.streams import Sensor, constant_velocity, detect, in_order, scans

CART = Sensor("cart", "cartesian", period_s=0.5, std_m=2.0)
RADAR = Sensor("radar", "radar", period_s=0.5, offset_s=0.25, range_std_m=2.0, bearing_std_rad=0.003,
               position_m=(-600.0, -400.0))
MODELS = {
    "cv": MotionConfig(model="cv", accel_psd_m2s3=0.5),
    "ca": MotionConfig(model="ca", jerk_psd_m2s5=0.5),
    "ct": MotionConfig(model="ct", accel_psd_m2s3=0.5, turn_psd_rad2s3=0.01),
    "imm-cv-ct": MotionConfig(model="imm", modes=[
        ModeConfig(model="cv", accel_psd_m2s3=0.25, sojourn_s=20.0),
        ModeConfig(model="ct", accel_psd_m2s3=0.25, turn_psd_rad2s3=0.01, sojourn_s=5.0)]),
    "imm-cv-cv": MotionConfig(model="imm", modes=[
        ModeConfig(model="cv", accel_psd_m2s3=0.1, sojourn_s=20.0),
        ModeConfig(model="cv", accel_psd_m2s3=10.0, sojourn_s=2.0)]),
    "imm-cv-cv-ct": MotionConfig(model="imm", modes=[  # three modes: the mixture's numpy branch
        ModeConfig(model="cv", accel_psd_m2s3=0.1, sojourn_s=20.0),
        ModeConfig(model="cv", accel_psd_m2s3=10.0, sojourn_s=2.0),
        ModeConfig(model="ct", accel_psd_m2s3=0.25, turn_psd_rad2s3=0.01, sojourn_s=5.0)]),
    "ukf-cv": MotionConfig(model="cv", accel_psd_m2s3=0.5, filter="ukf"),
    "ukf-ct": MotionConfig(model="ct", accel_psd_m2s3=0.5, turn_psd_rad2s3=0.01, filter="ukf"),
}
BATCHED = {"cv": BatchedGate, "ca": BatchedGate, "ct": BatchedGate, "imm-cv-ct": BatchedIMMGate,
           "imm-cv-cv": BatchedIMMGate, "imm-cv-cv-ct": BatchedIMMGate,
           "ukf-cv": BatchedUKFGate, "ukf-ct": BatchedUKFGate}


def run(motion: MotionConfig, gate: type, seed: int) -> list:
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=4, duration_s=20.0, rng=rng, crossing=True, manoeuvre=(1, 8.0, 12.0, 0.2))
    dets = in_order(*(detect(truth, s, rng=rng, pd=0.9, clutter_mean=2.0, region_m=(-300, 300, -300, 300))
                      for s in (CART, RADAR)))
    tr = Tracker(TrackerConfig(sensors=[CART.config(), RADAR.config()], motion=motion))
    tr.ctx = dataclasses.replace(tr.ctx, gater=gate(tr.filter, tr.ctx.gater.g))  # type: ignore[attr-defined]
    out = []
    for batch in scans(dets):
        r = tr.process([d.det for d in batch])
        out.append([(a.seq, a.outcome.value, a.track_id, a.nis) for a in r.each_association()])
        out.append([(e.track_id, e.status, e.x, e.P, e.nis) for e in r.estimates])
    return out


@pytest.mark.parametrize("name", sorted(MODELS))
def test_batched_and_per_pair_gates_agree(name: str) -> None:
    motion = MODELS[name]
    tr = Tracker(TrackerConfig(sensors=[CART.config()], motion=motion))
    assert isinstance(tr.ctx.gater, BATCHED[name]), "the shipped choice for this model is a batched gate"
    a, b = run(motion, BATCHED[name], 7), run(motion, PerPairGate, 7)
    assert len(a) == len(b) > 40
    n = 0
    for ra, rb in zip(a, b, strict=True):
        assert len(ra) == len(rb)
        for xa, xb in zip(ra, rb, strict=True):
            for va, vb in zip(xa, xb, strict=True):
                if isinstance(va, np.ndarray | float):
                    np.testing.assert_allclose(va, vb, rtol=1e-12, atol=1e-12)
                    n += 1
                else:
                    assert va == vb
    assert n > 500
