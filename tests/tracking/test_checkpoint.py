"""A tracker checkpointed and resumed is the tracker that stopped (issue #13: restart)."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import pytest

from fusion.config import LifecycleConfig, ModeConfig, MotionConfig, TimeConfig, TrackerConfig
from fusion.io.checkpoint import MAGIC, CheckpointError, read_checkpoint, write_checkpoint
from fusion.tracking.tracker import Tracker
from tests.tracking.helpers import track_snapshot
from tests.tracking.streams import Sensor, constant_velocity, detect, in_order, scans

CART = Sensor("cart", "cartesian", period_s=0.5, std_m=2.0)
RADAR = Sensor("radar", "radar", period_s=0.5, offset_s=0.25, range_std_m=2.0, bearing_std_rad=0.003,
               position_m=(-600.0, -400.0))
MOTIONS = {
    "cv": MotionConfig(model="cv", accel_psd_m2s3=0.5),
    "imm": MotionConfig(model="imm", modes=[ModeConfig(model="cv", accel_psd_m2s3=0.25, sojourn_s=20.0),
                                            ModeConfig(model="ct", accel_psd_m2s3=0.25, turn_psd_rad2s3=0.01,
                                                       sojourn_s=5.0)]),
}


def _config(motion: MotionConfig) -> TrackerConfig:
    return TrackerConfig(sensors=[CART.config(), RADAR.config()], motion=motion,
                         lifecycle=LifecycleConfig(confirm_m=3, confirm_n=5), time=TimeConfig(lag_s=1.0))


def _batches(seed: int = 4):
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=3, duration_s=20.0, rng=rng, spread_m=300.0)
    dets = in_order(*(detect(truth, s, rng=rng, pd=0.9, clutter_mean=1.0, region_m=(-400, 400, -400, 400))
                      for s in (CART, RADAR)))
    return [[x.det for x in b] for b in scans(dets)]


@pytest.mark.parametrize("name", sorted(MOTIONS))
def test_a_resumed_tracker_continues_exactly(name: str, tmp_path: Path) -> None:
    cfg = _config(MOTIONS[name])
    batches = _batches()
    half = len(batches) // 2
    straight = Tracker(cfg)
    first = Tracker(cfg)
    for b in batches[:half]:
        straight.process(b)
        first.process(b)
    write_checkpoint(tmp_path / "t.ck", first)
    resumed = read_checkpoint(tmp_path / "t.ck", cfg)
    assert resumed is not None and resumed.tracks == len(first.tracks) > 0 and 0 <= resumed.age_s < 60
    second = resumed.tracker
    assert track_snapshot(second) == track_snapshot(first)
    for b in batches[half:]:
        a, c = straight.process(b), second.process(b)
        assert [(e.key, e.status, e.x.tobytes(), e.P.tobytes()) for e in a.estimates] == \
               [(e.key, e.status, e.x.tobytes(), e.P.tobytes()) for e in c.estimates]
        assert [ev.key for ev in a.events] == [ev.key for ev in c.events]
    assert track_snapshot(second) == track_snapshot(straight)
    assert second.counts == straight.counts


def test_data_before_the_checkpoint_are_too_late_after_resuming(tmp_path: Path) -> None:
    cfg = _config(MOTIONS["cv"])
    batches = _batches()
    tr = Tracker(cfg)
    for b in batches[:10]:
        tr.process(b)
    write_checkpoint(tmp_path / "t.ck", tr)
    again = read_checkpoint(tmp_path / "t.ck", cfg).tracker  # type: ignore[union-attr]
    late = batches[9][0]
    (r,) = again.process([late]).refused
    assert r.reason.value == "too_late"


@pytest.mark.parametrize(("damage", "message"), [
    (lambda b: b"not a checkpoint", "not a fusion checkpoint"),
    (lambda b: b[: len(b) // 2], "damaged or of another version"),
    (lambda b: MAGIC + msgspec.msgpack.encode({"written_wall_ns": 1, "state": {"format": "x"}}),
     "damaged or of another version"),
], ids=["foreign", "torn", "another-format"])
def test_a_bad_checkpoint_is_refused_with_the_reason(damage, message: str, tmp_path: Path) -> None:
    cfg = _config(MOTIONS["cv"])
    tr = Tracker(cfg)
    for b in _batches()[:6]:
        tr.process(b)
    p = tmp_path / "t.ck"
    write_checkpoint(p, tr)
    p.write_bytes(damage(p.read_bytes()))
    with pytest.raises(CheckpointError, match=message):
        read_checkpoint(p, cfg)


def test_a_checkpoint_of_another_configuration_is_refused(tmp_path: Path) -> None:
    tr = Tracker(_config(MOTIONS["cv"]))
    tr.process(_batches()[0])
    write_checkpoint(tmp_path / "t.ck", tr)
    with pytest.raises(CheckpointError, match="another configuration"):
        read_checkpoint(tmp_path / "t.ck", _config(MOTIONS["imm"]))
    assert read_checkpoint(tmp_path / "missing.ck", _config(MOTIONS["cv"])) is None


def test_a_checkpoint_of_another_namespace_is_refused(tmp_path: Path) -> None:
    """Its tracks are of other targets: a service on another namespace (same configuration,
    same folder) resumed them as its own confirmed tracks."""
    cfg = _config(MOTIONS["cv"])
    tr = Tracker(cfg)
    for b in _batches()[:6]:
        tr.process(b)
    write_checkpoint(tmp_path / "t.ck", tr, namespace="demo")
    with pytest.raises(CheckpointError, match="written by the service on namespace 'demo', not 'other'"):
        read_checkpoint(tmp_path / "t.ck", cfg, namespace="other")
    assert read_checkpoint(tmp_path / "t.ck", cfg, namespace="demo").tracks == len(tr.tracks)  # type: ignore[union-attr]
    assert read_checkpoint(tmp_path / "t.ck", cfg).tracks == len(tr.tracks)  # type: ignore[union-attr]  # not a service
    write_checkpoint(tmp_path / "old.ck", tr)  # as written before checkpoints said their namespace
    assert read_checkpoint(tmp_path / "old.ck", cfg, namespace="other").tracks == len(tr.tracks)  # type: ignore[union-attr]


def test_writing_replaces_the_old_checkpoint_whole(tmp_path: Path) -> None:
    cfg = _config(MOTIONS["cv"])
    tr = Tracker(cfg)
    p = tmp_path / "t.ck"
    sizes = set()
    for b in _batches()[:8]:
        tr.process(b)
        sizes.add(write_checkpoint(p, tr))
        assert read_checkpoint(p, cfg).tracks == len(tr.tracks)  # type: ignore[union-attr]
    assert len(sizes) > 1 and sorted(x.name for x in tmp_path.iterdir()) == ["t.ck"]  # no temporary left
