"""Small test-side utilities: tracker construction, the consumer's view of estimates, track snapshots."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from fusion.config import LifecycleConfig, MotionConfig, TimeConfig, TrackerConfig
from fusion.publication import PublishedView
from fusion.tracking.results import Estimate, StepResult
from fusion.tracking.tracker import Tracker
from tests.tracking.streams import Sensor

EstimateKey = tuple[int, int, str]


def make_tracker(
    sensors: Iterable[Sensor],
    *,
    motion: MotionConfig | None = None,
    lifecycle: LifecycleConfig | None = None,
    time: TimeConfig | None = None,
) -> Tracker:
    cfg = TrackerConfig(
        sensors=[s.config() for s in sensors],
        motion=motion or MotionConfig(),
        lifecycle=lifecycle or LifecycleConfig(),
        time=time or TimeConfig(),
    )
    return Tracker(cfg)


class Consumer:
    """What a downstream consumer holds: the latest revision per (track_id, t_ns, sensor_id),
    retracted keys dropped; the events reported and not withdrawn; and, through a
    PublishedView, what a subscriber of the published estimates holds. It also checks that
    revisions of a key only ever increase and that only reported events are withdrawn."""

    def __init__(self) -> None:
        self.latest: dict[EstimateKey, Estimate] = {}
        self.last_revision: dict[EstimateKey, int] = {}
        self.events: set[tuple[str, int, int, str]] = set()
        self.view = PublishedView()
        self.subscribed: dict[EstimateKey, Estimate] = {}
        self.subscribed_events: set[tuple[str, int, int, str]] = set()
        self.n_revised = 0
        self.n_retracted = 0
        self.n_withdrawn = 0

    def take(self, result: StepResult) -> None:
        for ev in result.events:
            if ev.retracted:
                assert ev.key in self.events, f"withdrawn but never reported: {ev}"
                self.events.discard(ev.key)
                self.n_withdrawn += 1
            else:
                assert ev.key not in self.events, f"reported twice: {ev}"
                self.events.add(ev.key)
        for e in self.view.select(result.estimates):
            self.subscribed[e.key] = e
        for ev in self.view.select_events(result.events):
            if ev.retracted:
                self.subscribed_events.discard(ev.key)
            else:
                self.subscribed_events.add(ev.key)
        for e in result.estimates:
            key = (e.track_id, e.t_ns, e.sensor_id)
            prev = self.last_revision.get(key)
            assert prev is None or e.revision > prev, f"revision {e.revision} of {key} after {prev}"
            assert (prev is None) == (e.revision == 0), f"{key}: first revision {e.revision}"
            self.last_revision[key] = e.revision
            if e.revision > 0:
                self.n_revised += 1
            if e.status == "retracted":
                self.n_retracted += 1
                self.latest.pop(key, None)
            else:
                self.latest[key] = e

    def snapshot(self) -> dict[EstimateKey, tuple[str, int, bytes, bytes]]:
        return {k: (e.status, e.seq, e.x.tobytes(), e.P.tobytes()) for k, e in sorted(self.latest.items())}

    def published(self) -> dict[EstimateKey, tuple[int, bytes, bytes]]:
        """The subscriber's view: latest published revision per key, confirmed ones only."""
        return {k: (e.seq, e.x.tobytes(), e.P.tobytes()) for k, e in sorted(self.subscribed.items())
                if e.status == "confirmed"}


def data_counts(tracker: Tracker) -> dict[str, object]:
    """The counts that describe what the data did (not how it arrived)."""
    c = tracker.counts
    return {"applied": c.applied, "updates": c.updates, "births": c.births, "unassigned": c.unassigned,
            "births_refused_capacity": c.births_refused_capacity, "confirmations": c.confirmations,
            "deletions": dict(c.deletions), "numerical_skips": c.numerical_skips}


def track_snapshot(tracker: Tracker) -> list[tuple[int, str, int, int, bytes, bytes]]:
    """Tracks by id with their status, counters and exact state bytes."""
    return sorted(
        (t.id, t.status.label, t.hits, t.state.t_ns, t.state.x.tobytes(), t.state.P.tobytes()) for t in tracker.tracks
    )


def positions_at(tracker: Tracker, t_ns: int, *, confirmed_only: bool = True) -> tuple[list[int], np.ndarray]:
    """Track ids and positions extrapolated (constant velocity) from each track's last update to t_ns."""
    tracks = tracker.confirmed() if confirmed_only else tracker.tracks
    ids = [t.id for t in tracks]
    pos = np.array(
        [[t.state.x[0] + t.state.x[1] * (t_ns - t.state.t_ns) / 1e9,
          t.state.x[2] + t.state.x[3] * (t_ns - t.state.t_ns) / 1e9] for t in tracks]
    ).reshape(-1, 2)
    return ids, pos
