"""What the service publishes, and the view a subscriber ends up with.

Rule: an estimate is published when it is confirmed (or when tentative ones are published at
all); once a key (track_id, t_ns, sensor_id) has been published, every later revision of it is
published too, whatever its status, retractions included. A subscriber keeps the latest
revision per key and drops keys whose latest revision is retracted or tentative: that view is
then the same for any arrival order (a replay that demotes a published estimate to tentative
publishes the demotion).

Events: confirmed, coasting and deleted events of the tracks whose estimates were published
(not born: every clutter return starts a track), and the withdrawal of any event published
before. A subscriber holding the events not withdrawn ends up with the same set for any arrival
order.

The snapshot (the `snapshot` queryable) follows the tracker, not the history of publications:
the latest published estimate of every live confirmed track.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable

from fusion.tracking.results import Estimate, EstimateKey, EventKind, TrackEvent
from fusion.tracking.trackset import Status, TrackSet


class PublishedView:
    def __init__(self, *, publish_tentative: bool = False) -> None:
        self.publish_tentative = publish_tentative
        self.latest: dict[EstimateKey, Estimate] = {}  # published keys -> latest published revision
        self.tracks: dict[int, int] = {}  # published track ids -> time of their latest published estimate
        self.events: dict[tuple[str, int, int, str], TrackEvent] = {}  # published, not withdrawn
        self._pruned_at: int | None = None
        self._due: dict[int, list[EstimateKey]] = {}  # t_ns -> the keys of `latest` at that time, for prune
        self._kept: list[EstimateKey] = []  # keys before the last prune's horizon kept as a track's current key

    def select(self, estimates: Iterable[Estimate]) -> tuple[Estimate, ...]:
        """The estimates of one step to publish (see the module docstring); remembers them."""
        out = []
        latest, tracks, tentative, due = self.latest, self.tracks, self.publish_tentative, self._due
        for e in estimates:
            k = e.key
            st = e.status
            if k in latest or st == "confirmed" or (tentative and st == "tentative"):
                if k not in latest:
                    due.setdefault(k[1], []).append(k)
                latest[k] = e
                tid, t = e.track_id, e.t_ns
                last = tracks.get(tid)
                tracks[tid] = t if last is None or t > last else last
                out.append(e)
        return tuple(out)

    def select_events(self, events: Iterable[TrackEvent]) -> tuple[TrackEvent, ...]:
        """The events of one step to publish (see the module docstring); call after `select`."""
        out = []
        for ev in events:
            if ev.retracted:
                if self.events.pop(ev.key, None) is not None:
                    out.append(ev)
            elif ev.kind != EventKind.BORN and ev.track_id in self.tracks:
                self.events[ev.key] = ev
                out.append(ev)
        return tuple(out)

    def snapshot(self, tracks: TrackSet) -> list[Estimate]:
        """The latest published estimate of each live confirmed track, by track id."""
        out = []
        for k in self._current(tracks, confirmed_only=True):
            e = self.latest.get(k)
            if e is not None and e.status == "confirmed":
                out.append(e)
        return sorted(out, key=lambda e: e.track_id)

    @staticmethod
    def _current(tracks: TrackSet, *, confirmed_only: bool = False) -> set[EstimateKey]:
        """The key of every live track's current estimate: (id, time and sensor of its last update)."""
        names = tracks.layout.sensors
        ids, ts, last = tracks.ids, tracks.t_ns, tracks.last_sensor
        if confirmed_only:
            rows = tracks.status == Status.CONFIRMED.value
            ids, ts, last = ids[rows], ts[rows], last[rows]
        return {(i, t, names[s]) for i, t, s in zip(ids.tolist(), ts.tolist(), last.tolist(), strict=True)}

    def prune(self, horizon_ns: int | None, tracks: TrackSet, *, every_ns: int = 250_000_000) -> None:
        """Forget keys before the horizon (they can no longer be revised) unless they hold a live
        track's current estimate. Runs when the horizon has moved by `every_ns` since last time.

        Visits only the keys due: those of the times before the horizon (`_due`, filled by
        select) and the current keys it kept last time, not every key of the window; what it
        keeps is the same as `{k for k in latest if not (k[1] < horizon_ns and k not in current)}`
        (tests/test_publication.py). At 10k measurements/s the window holds ~20 000 keys and
        forgetting each frees an Estimate (~2 us): run often, each run frees only what is due. (A
        horizon never moves back: `horizon_ns - _pruned_at < every_ns` returns before.)"""
        if horizon_ns is None or (self._pruned_at is not None and horizon_ns - self._pruned_at < every_ns):
            return
        self._pruned_at = horizon_ns
        due, latest = self._due, self.latest
        times = [t for t in due if t < horizon_ns]
        if times or self._kept:
            current = self._current(tracks)
            kept: list[EstimateKey] = []
            for k in itertools.chain(self._kept, *(due.pop(t) for t in times)):
                if k in current:
                    kept.append(k)
                else:
                    del latest[k]
            self._kept = kept
        live = {int(i) for i in tracks.ids.tolist()}
        for tid in [t for t, last in self.tracks.items() if last < horizon_ns and t not in live]:
            del self.tracks[tid]
        for k in [k for k in self.events if k[2] < horizon_ns]:
            del self.events[k]
