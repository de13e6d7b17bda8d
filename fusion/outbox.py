"""What the service sends after each batch, over its Zenoh session, and how much of it.

  fusion/<ns>/tracks/<id>     each estimate to publish (fusion.pipeline's `to_publish`), on one
                              declared publisher per track (fusion.io.zenoh_publishers); the
                              snapshot answers keep the same bytes (fusion.snapshot_answers)
  fusion/<ns>/events/<id>     lifecycle events (fusion.publication)
  fusion/<ns>/smoothed/<id>   with [publication] smooth_lag: fixed-lag smoothed estimates
                              (fusion.fixed_lag)
  fusion/<ns>/predicted       with [publication] period_s: every confirmed track predicted to
                              each period's time the data have passed (fusion.prediction)

Every put uses congestion control BLOCK: an estimate is never dropped for a slow subscriber.
"""

from __future__ import annotations

from typing import Any

from fusion import messages as m
from fusion.config import PublicationConfig
from fusion.fixed_lag import FixedLagSmoother, smoothed_key
from fusion.io import wire
from fusion.io.zenoh_publishers import KeyedPublishers
from fusion.pipeline import Output
from fusion.prediction import Cadence, encode_predicted, predicted_key
from fusion.snapshot_answers import SnapshotAnswers
from fusion.tracking.tracker import Tracker


class Outbox:
    """The service's publications (namespace `ns`), counted by kind; sent on the session given
    to `open` until `close`."""

    def __init__(self, ns: str, tracker: Tracker, snapshots: SnapshotAnswers, publication: PublicationConfig) -> None:
        import zenoh

        self._session: Any = None
        self._tracks: KeyedPublishers | None = None  # one declared publisher per published track
        self._ns = ns
        self._tracker = tracker
        self._snapshots = snapshots
        self._block = zenoh.CongestionControl.BLOCK
        period_ns = round(publication.period_s * 1e9)
        self._cadence = Cadence(period_ns) if period_ns > 0 else None
        lag = publication.smooth_lag
        self._smoother = FixedLagSmoother(tracker, lag) if lag > 0 else None
        self.published = 0  # estimates
        self.events = 0
        self.smoothed = 0
        self.predicted = 0  # periodic predicted snapshots

    def open(self, session: Any) -> None:
        ns = self._ns
        self._session = session
        self._tracks = KeyedPublishers(session, lambda tid: wire.track_key(ns, tid), congestion_control=self._block)

    def send(self, out: Output) -> None:
        """A batch's publications: its estimates, its events, the smoothed estimates its
        results release, and the predicted snapshots whose times it passed."""
        pubs = self._tracks
        if pubs is None:
            raise RuntimeError("Outbox.send before open")
        tr, put, block = self._tracker, self._session.put, self._block
        payloads = wire.estimates_encoder(tr.layout, tr.model_name)(out.to_publish)
        for e, payload in zip(out.to_publish, payloads, strict=True):
            pubs.put(e.track_id, payload)
        self.published += len(payloads)
        self._snapshots.published(out.to_publish, payloads)  # the snapshot reuses the bytes
        for ev in out.events_to_publish:
            put(m.event_key(self._ns, ev.track_id), m.encode(wire.event_message(ev)), congestion_control=block)
        self.events += len(out.events_to_publish)
        if self._smoother is not None:
            enc = wire.estimate_encoder(tr.layout, tr.model_name)
            for e in self._smoother.update(out.result.estimates):
                put(smoothed_key(self._ns, e.track_id), enc(e), congestion_control=block)
                self.smoothed += 1
        if self._cadence is not None:
            first = min((p.t_ns for p in out.result.measurements), default=None)
            for t_ns in self._cadence.due(tr.now_ns, first):
                put(predicted_key(self._ns), encode_predicted(tr, t_ns), congestion_control=block)
                self.predicted += 1

    def retire(self, live_ids: set[int]) -> None:
        """Deleted tracks give their publishers back."""
        if self._tracks is not None:
            self._tracks.retire(live_ids)

    def close(self) -> None:
        """The track publishers undeclared (the session is its owner's to close)."""
        if self._tracks is not None:
            self._tracks.close()
        self._session = self._tracks = None
