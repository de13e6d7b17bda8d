"""Track lifecycle: M-of-N confirmation, deletion of unconfirmed clutter tracks and of lost
targets (with the reason), and ids never reused within a run."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import LifecycleConfig
from fusion.tracking.detection import Detection
from fusion.tracking.trackset import track_id_for
from tests.tracking.helpers import Consumer, make_tracker
from tests.tracking.streams import NS_PER_S, Sensor, constant_velocity, detect, in_order, scans

S = NS_PER_S
CART = Sensor("cart", "cartesian", period_s=0.5, std_m=1.0)


MN = [(3, 5), (2, 3), (4, 4), (1, 3), (1, 1)]


@pytest.mark.parametrize(("m", "n"), MN, ids=[f"{m}of{n}" for m, n in MN])
def test_not_confirmed_before_m_hits(m: int, n: int) -> None:
    rng = np.random.default_rng(7)
    tr = make_tracker([CART], lifecycle=LifecycleConfig(confirm_m=m, confirm_n=n))
    tid = track_id_for("cart", 0, 0)
    confirmed_at = None
    for k in range(8):
        z = np.array([10.0 * k * 0.5, 0.0]) + rng.normal(0.0, 1.0, 2)  # 10 m/s along x, every hit
        result = tr.process([Detection.of("cart", k * S // 2, k, z)])
        (e,) = result.estimates
        assert e.track_id == tid
        hits = k + 1
        if hits < m:
            assert e.status == "tentative", f"confirmed after {hits} hits with M={m}"
        if any(ev.kind == "confirmed" for ev in result.events):
            assert confirmed_at is None
            confirmed_at = hits
    assert confirmed_at == m


def test_confirmation_needs_m_hits_within_n_scans() -> None:
    """Hits in scans 0 and 1, misses in 2-4: 2 of 5, so the track is dropped after scan 4 unconfirmed."""
    tr = make_tracker([CART], lifecycle=LifecycleConfig(confirm_m=3, confirm_n=5))
    pattern = [True, True, False, False, False, True]  # scan k: does the target return?
    events = []
    for k, hit in enumerate(pattern):
        z = [0.0, 0.0] if hit else [5000.0 + 1000.0 * k, 5000.0]  # a miss: a far clutter return drives the scan
        events += tr.process([Detection.of("cart", k * S // 2, k, z)]).events
    tid = track_id_for("cart", 0, 0)
    assert ("deleted", tid, "not confirmed") in {(e.kind, e.track_id, e.reason) for e in events}
    assert not any(e.kind == "confirmed" for e in events)


def test_isolated_clutter_tracks_die_tentative_within_n_scans() -> None:
    """One target plus one clutter return per scan, each at a fresh point of a 1 km grid (so no
    two clutter returns ever share a gate): no clutter track is ever confirmed, and each is
    deleted ("not confirmed") within confirm_n scans of its birth."""
    lc = LifecycleConfig(confirm_m=3, confirm_n=5)
    tr = make_tracker([CART], lifecycle=lc)
    rng = np.random.default_rng(11)
    grid = [np.array([2000.0 + 1000.0 * (i % 20), 2000.0 + 1000.0 * (i // 20)]) for i in range(200)]
    born_scan: dict[int, int] = {}
    deleted: dict[int, tuple[int, str]] = {}
    confirmed: set[int] = set()
    target_tid = track_id_for("cart", 0, 0)
    seq = 0
    for k in range(60):
        dets = [Detection.of("cart", k * S // 2, seq, rng.normal(0.0, 1.0, 2))]
        dets.append(Detection.of("cart", k * S // 2, seq + 1, grid[k] + rng.normal(0.0, 1.0, 2)))
        seq += 2
        for ev in tr.process(dets).events:
            if ev.kind == "born":
                born_scan[ev.track_id] = k
            elif ev.kind == "deleted":
                deleted[ev.track_id] = (k, ev.reason)
            elif ev.kind == "confirmed":
                confirmed.add(ev.track_id)
    assert confirmed == {target_tid}
    clutter = set(born_scan) - {target_tid}
    assert len(clutter) == 60  # every clutter return started a track
    for tid in clutter:
        if born_scan[tid] <= 60 - lc.confirm_n:
            k, why = deleted[tid]
            assert why == "not confirmed"
            assert k - born_scan[tid] + 1 <= lc.confirm_n
    assert len(tr.tracks) <= lc.confirm_n  # the target and at most confirm_n - 1 young clutter tracks


@pytest.mark.parametrize(
    ("lifecycle", "reason", "deleted_after_s"),
    [
        (LifecycleConfig(max_misses=10, coast_s=3.0), "coasted", 3.5),  # 7 scans of 0.5 s > 3 s
        (LifecycleConfig(max_misses=4, coast_s=30.0), "misses", 2.5),  # the 5th scan without a hit
        (LifecycleConfig(max_misses=100, coast_s=60.0, max_position_std_m=20.0), "covariance", None),
    ],
    ids=["coasted", "misses", "covariance"],
)
def test_a_vanished_target_is_deleted_with_the_reason(lifecycle: LifecycleConfig, reason: str,
                                                      deleted_after_s: float | None) -> None:
    """Two targets; target 0 vanishes at t = 10 s, target 1 keeps the scans coming."""
    rng = np.random.default_rng(5)
    truth = constant_velocity(n_targets=2, duration_s=30.0, rng=rng, spread_m=300.0,
                              lifetimes_s=[(0.0, 10.0), (0.0, 60.0)])
    dets = in_order(detect(truth, CART, rng=rng))
    tr = make_tracker([CART], lifecycle=lifecycle)
    consumer = Consumer()
    owner: dict[int, int] = {}
    deletions = []
    for batch in scans(dets):
        result = tr.process([d.det for d in batch])
        consumer.take(result)
        for a in result.each_association():
            origin = next(d.origin for d in batch if d.det.seq == a.seq)
            if a.track_id is not None:
                owner.setdefault(a.track_id, origin)
        deletions += [ev for ev in result.events if ev.kind == "deleted"]
    lost = [ev for ev in deletions if owner.get(ev.track_id) == 0]
    assert len(lost) == 1, deletions
    ev = lost[0]
    assert ev.reason == reason
    last_hit_s = 9.5
    if deleted_after_s is not None:
        assert ev.t_ns == round((last_hit_s + deleted_after_s) * S)
    assert all(owner.get(e.track_id) != 1 for e in deletions), "the other target's track lives on"
    assert not any(k[0] == ev.track_id and k[1] > ev.t_ns for k in consumer.latest), "no estimate after deletion"


def test_track_ids_are_never_reused_in_a_run() -> None:
    rng = np.random.default_rng(23)
    truth = constant_velocity(n_targets=4, duration_s=40.0, rng=rng, crossing=True)
    dets = in_order(detect(truth, CART, rng=rng, pd=0.8, clutter_mean=4.0, region_m=(-300, 300, -300, 300)))
    tr = make_tracker([CART])
    born: list[int] = []
    gone: set[int] = set()
    for batch in scans(dets):
        result = tr.process([d.det for d in batch])
        # (a track may be updated and deleted in the same scan: check against earlier deletions)
        assert not {e.track_id for e in result.estimates} & gone, "an estimate of a deleted track"
        for ev in result.events:
            if ev.kind == "born":
                assert ev.track_id not in gone, "an id came back after its track was deleted"
                born.append(ev.track_id)
            elif ev.kind == "deleted":
                gone.add(ev.track_id)
        ids = [t.id for t in tr.tracks]
        assert len(ids) == len(set(ids))
    assert len(born) == len(set(born)) > 100
    assert len(gone) > 100


def _cam_track_and_a_radar(radar_cfg):
    """A target at rest seen by a camera every 0.5 s for 3 s, and a radar elsewhere."""
    from fusion.config import CartesianSensorConfig, TrackerConfig
    from fusion.tracking.tracker import Tracker

    cfg = TrackerConfig(sensors=[CartesianSensorConfig(id="cam", std_m=[1.0, 1.0]), radar_cfg],
                        lifecycle=LifecycleConfig(max_misses=10, coast_s=3.0))
    tr = Tracker(cfg)
    rng = np.random.default_rng(9)
    for k in range(7):
        tr.process([Detection.of("cam", k * S // 2, k, rng.normal(0.0, 1.0, 2))])
    (track,) = tr.confirmed()
    return tr, track.id


def test_another_sensors_burst_does_not_delete_a_track() -> None:
    """60 separately timestamped radar returns far away, between two camera scans: the radar
    never saw the camera's target, so they are no chances for its track (issue #9, defect 7)."""
    from fusion.config import RadarSensorConfig

    tr, tid = _cam_track_and_a_radar(RadarSensorConfig(id="radar", position_m=[5000.0, 0.0], range_std_m=5.0,
                                                       bearing_std_rad=0.003))
    events = []
    for i in range(60):  # 60 returns in 0.4 s, each its own scan
        t = 3 * S + (i + 1) * S // 150
        events += tr.process([Detection.of("radar", t, i, [200.0 + 10.0 * i, 0.5])]).events
    events += tr.process([Detection.of("cam", 3 * S + S // 2, 7, [0.0, 0.0])]).events
    assert not [e for e in events if e.track_id == tid and e.kind == "deleted"]
    assert tid in {t.id for t in tr.confirmed()}
    i = tr.track_set.index_of(tid)
    assert tr.track_set.misses[i] == 0 and tr.track_set.chances[i] == 8


def test_a_covering_sensor_that_never_sees_the_track_wears_it_down() -> None:
    """A radar whose declared coverage holds the target but which never detects it: its scans
    are chances, so the track is deleted after max_misses of them (and only by them: the
    camera stops reporting, coast_s is long)."""
    from fusion.config import RadarSensorConfig

    tr, tid = _cam_track_and_a_radar(RadarSensorConfig(id="radar", position_m=[1000.0, 0.0], max_range_m=2000.0,
                                                       range_std_m=5.0, bearing_std_rad=0.003))
    deleted_at = None
    for i in range(12):  # radar scans every 0.1 s, each with one far return only
        t = 3 * S + (i + 1) * S // 10
        for e in tr.process([Detection.of("radar", t, i, [1500.0, 3.0])]).events:
            if e.track_id == tid and e.kind == "deleted":
                deleted_at, reason = i, e.reason
    assert deleted_at == 10 and reason == "misses"  # the 11th chance in a row without a hit > max_misses
