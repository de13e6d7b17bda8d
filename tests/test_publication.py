"""The published view: once a key is published every later revision of it is, and the snapshot
follows the tracker (issue #9, defect 1)."""

from __future__ import annotations

from fusion.config import CartesianSensorConfig, LifecycleConfig, TrackerConfig
from fusion.publication import PublishedView
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker

MS = 1_000_000


def _tracker() -> Tracker:
    sensors = [CartesianSensorConfig(id=s, std_m=[1.0, 1.0]) for s in ("s1", "s2", "s3")]
    return Tracker(TrackerConfig(sensors=sensors, lifecycle=LifecycleConfig(confirm_m=3, confirm_n=5)))


def test_a_replay_that_demotes_a_published_estimate_publishes_the_demotion() -> None:
    """s1 at 0 ms (0, 0), s2 at 50 ms (6, 0), s1 at 100 ms (1, 0): confirmed and published. Then
    s3 at 20 ms (10, 0), delivered last, starts a second track that takes s2's return: the
    estimate at 100 ms is tentative after all. Its new revision must reach subscribers, and the
    snapshot must drop the track."""
    tr, view = _tracker(), PublishedView()
    subscriber: dict = {}
    for d in (Detection.of("s1", 0, 0, [0.0, 0.0]), Detection.of("s2", 50 * MS, 0, [6.0, 0.0]),
              Detection.of("s1", 100 * MS, 1, [1.0, 0.0])):
        for e in view.select(tr.process([d]).estimates):
            subscriber[e.key] = e
    (first,) = tr.confirmed()
    key = (first.id, 100 * MS, "s1")
    assert subscriber[key].status == "confirmed"
    assert [e.track_id for e in view.snapshot(tr.track_set)] == [first.id]

    published = view.select(tr.process([Detection.of("s3", 20 * MS, 0, [10.0, 0.0])]).estimates)
    for e in published:
        subscriber[e.key] = e
    assert not tr.confirmed(), "the replay leaves no confirmed track"
    assert key in {e.key for e in published}, "the demotion of a published estimate was not published"
    assert subscriber[key].status == "tentative" and subscriber[key].revision == 1
    assert view.snapshot(tr.track_set) == []


def test_tentative_estimates_never_published_stay_unpublished() -> None:
    tr, view = _tracker(), PublishedView()
    assert view.select(tr.process([Detection.of("s1", 0, 0, [0.0, 0.0])]).estimates) == ()
    assert PublishedView(publish_tentative=True).select(
        _tracker().process([Detection.of("s1", 0, 0, [0.0, 0.0])]).estimates)


def _pruned_as_before(latest: dict, horizon_ns: int, tracks: object) -> set:
    """The keys the view keeps after a prune, as first written: every key before the horizon
    is dropped unless it holds a live track's current estimate."""
    current = PublishedView._current(tracks)  # type: ignore[arg-type]
    return {k for k in latest if not (k[1] < horizon_ns and k not in current)}


def test_prune_keeps_exactly_the_keys_the_rule_keeps() -> None:
    """Three sensors, five targets and clutter over 12 s (seeded), horizons of the tracker's 2 s
    window: after every prune the view holds exactly what the rule keeps (the heap by time
    visits only what is due, kept current keys are looked at again: one target falls silent for
    4 s and comes back)."""
    import numpy as np

    from fusion.config import TimeConfig

    rng = np.random.default_rng(11)
    sensors = [CartesianSensorConfig(id=s, std_m=[1.0, 1.0]) for s in ("s1", "s2", "s3")]
    tr = Tracker(TrackerConfig(sensors=sensors, lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3, max_misses=200),
                               time=TimeConfig(lag_s=2.0)))
    view = PublishedView()
    starts = rng.uniform(-500, 500, size=(5, 2))
    seq = dict.fromkeys(("s1", "s2", "s3"), 0)
    prunes, kept_seen = 0, False
    for k in range(120):
        t = k * 100 * MS
        dets = []
        for s in ("s1", "s2", "s3"):
            for j, p in enumerate(starts):
                if j == 4 and 40 < k <= 80:
                    continue  # silent for 4 s: its track's current key, before the horizon, is kept until it
                    # comes back and updates the track
                z = p + np.array([10.0, 5.0]) * t / 1e9 + rng.normal(0, 1, 2)
                dets.append(Detection.of(s, t, seq[s], z))
                seq[s] += 1
            if rng.random() < 0.5:
                dets.append(Detection.of(s, t, seq[s], rng.uniform(-2000, 2000, 2)))
                seq[s] += 1
        view.select(tr.process(dets).estimates)
        before = dict(view.latest)
        h = tr.horizon_ns
        if h is not None and (view._pruned_at is None or h - view._pruned_at >= 300 * MS):
            expected = _pruned_as_before(before, h, tr.track_set)
            view.prune(h, tr.track_set, every_ns=300 * MS)
            assert set(view.latest) == expected, f"scan {k}"
            kept_seen = kept_seen or any(key[1] < h for key in expected)
            prunes += 1
    assert prunes > 10 and kept_seen
    assert len(view.latest) < 5 * 3 * 30  # the window's keys, not all of those published
