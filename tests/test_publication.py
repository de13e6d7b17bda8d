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
