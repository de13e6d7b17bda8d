"""The one path every sample takes, live or replayed: decode, validate, track, record, select.

`Pipeline.ingest(records)` takes raw samples `(arrival_ns, key, payload)` in arrival order and
returns the estimates to publish. `ingest(records, more=True)` says more samples follow at once
(a caller working off a backlog in batches of a fixed size): the measurements at the batch's end
that share the last one's scan (sensor, t_ns) wait for the next call, so a scan cut by the batch
limit is run once, whole, instead of run and then run again with its rest (a rescan: at 1000
targets, 16 % of the service's loop under a blast). Until then they count as not yet received
(`holding`); what the tracker computes is the same (it does not depend on batching). The live
service feeds it batches drained from its intake queue; `fusion replay` feeds it the same
records read back from a stream file. Admission is
decided one sample at a time in arrival order (the arrival time feeds the tracker's clock), so
a replay reproduces the live run's estimates exactly, however the records are batched.
`decoded(records)` decodes the measurements' payloads alone (it counts nothing): the live
service calls it on each part of a burst as it is drained, while the rest arrives, and hands
the result to `ingest(records, decoded=...)`, which checks, counts and refuses as it would
have had it decoded them itself.

A measurement must come on its own sensor's key (`.../meas/<sensor_id>`), truth on its own
target's key: anyone who may publish on one key cannot speak for another sensor.

Counts add up: received = applied + inputs + truth + sum(refused by reason), where received
is every sample handed to `ingest` and duplicates are refusals with reason "duplicate".
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fusion.errors import InvalidMessageError, MalformedMessageError, UnsupportedVersionError
from fusion.io.gaps import SeqGaps
from fusion.io.latency import LatencyTracker
from fusion.io.ratelimit import RateLimitedLog
from fusion.publication import PublishedView
from fusion.tracking.detection import ControlInput, Detection, Reason
from fusion.tracking.results import Counts, Estimate, StepResult, TrackEvent
from fusion.tracking.tracker import Tracker

log = logging.getLogger("fusion.pipeline")

Record = tuple[int, str, bytes]  # (arrival_ns, key expression, payload)


class Codec(Protocol):
    """Wire decoding the pipeline needs (fusion.io.wire implements it). Decoders raise
    MalformedMessageError or InvalidMessageError (fusion.errors)."""

    def kind(self, key: str) -> str:
        """"meas", "truth" or "other" for a key expression."""
        ...

    def key_id(self, key: str) -> str:
        """The sensor or target id a key names (its last segment)."""
        ...

    def detection(self, payload: bytes, arrival_ns: int | None = None) -> Detection: ...

    def detections(self, samples: Iterable[tuple[int | None, bytes]]) -> list[Detection | None]:
        """detection() of each (arrival_ns, payload), None where it would raise (no side effects)."""
        ...

    def control(self, payload: bytes, arrival_ns: int | None = None) -> ControlInput: ...

    def truth(self, payload: bytes, layout: tuple[str, ...]) -> tuple[str, int, np.ndarray] | None:
        """(target_id, t_ns, state in `layout`), None when the truth lacks a component."""
        ...


class Sink(Protocol):
    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None: ...

    def log_truths(self, truths: Sequence[tuple[str, int, np.ndarray]]) -> None: ...

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None: ...


@dataclass(frozen=True)
class Output:
    result: StepResult
    to_publish: tuple[Estimate, ...]
    events_to_publish: tuple[TrackEvent, ...] = ()


class Pipeline:
    """Decode, validate, track, record and select what to publish; see the module docstring."""

    def __init__(self, tracker: Tracker, codec: Codec, *, sink: Sink | None = None,
                 max_future_wall_ns: int | None = None, publish_tentative: bool = False,
                 warnings_per_minute: int = 60) -> None:
        self.tracker = tracker
        self.codec = codec
        self.sink = sink
        self.max_future_wall_ns = max_future_wall_ns
        self.view = PublishedView(publish_tentative=publish_tentative)
        self.latency = LatencyTracker()
        self.gaps = SeqGaps()  # seq gaps per configured sensor and publisher epoch
        self.warn = RateLimitedLog(log, per_minute=warnings_per_minute)
        self._received = 0
        self._truth = 0
        self._refused: dict[Reason, int] = {}  # at the edge, before the tracker
        self._refused_kinds = {"input": 0, "truth": 0, "other": 0}  # of them, by their keys' kind (not measurements)
        self._routes: dict[str, tuple[str, str]] = {}  # key expression -> (kind, key id)
        # per configured sensor, the batch's (latencies, epochs, seqs) not yet counted (_checked)
        self._pending: dict[str, tuple[list[int], list[int], list[int]]] = {}
        self._held: list[Detection] = []  # the last scan's measurements of a batch with more to come
        self._truths: list[tuple[str, int, np.ndarray]] = []  # the batch's truth, for the sink in one call

    @property
    def holding(self) -> int:
        """Measurements decoded and waiting for the rest of their scan (ingest's `more`)."""
        return len(self._held)

    def counts(self) -> Counts:
        """The tracker's counts with the edge's folded in (see the module docstring)."""
        c = self.tracker.counts
        refused = dict(c.refused)
        for r, n in self._refused.items():
            refused[r] = refused.get(r, 0) + n
        return dataclasses.replace(c, received=self._received - len(self._held), truth=self._truth,
                                   inputs_refused=c.inputs_refused + self._refused_kinds["input"],
                                   truth_refused=self._refused_kinds["truth"],
                                   other_refused=self._refused_kinds["other"], refused=dict(sorted(refused.items())))

    def _refuse(self, reason: Reason, key: str, detail: str, t_ns: int = 0, kind: str = "meas") -> None:
        """Count and say a sample refused at the edge; `kind` its key's (fusion.io.wire.Codec.kind)."""
        self._refused[reason] = self._refused.get(reason, 0) + 1
        if kind in self._refused_kinds:
            self._refused_kinds[kind] += 1
        self.warn.warn(reason.value, "refused sample on %s: %s: %s", key, reason.value, detail)
        if self.sink is not None:
            self.sink.log_text(t_ns, f"refused sample on {key}: {reason.value}: {detail}", "WARN")

    def _route(self, key: str) -> tuple[str, str]:
        """(kind, key id) of a key expression, remembered (a few keys carry every sample)."""
        r = self._routes.get(key)
        if r is None:
            if len(self._routes) >= 4096:
                self._routes.clear()
            r = self._routes[key] = (self.codec.kind(key), self.codec.key_id(key))
        return r

    def _decode(self, arrival_ns: int, key: str, payload: bytes) -> Detection | ControlInput | None:
        """One sample: a Detection or ControlInput for the tracker, or None (truth recorded, or
        refused and counted)."""
        kind, key_id = self._route(key)
        try:
            if kind == "meas":
                d = self.codec.detection(payload, arrival_ns)
            elif kind == "truth":
                tr = self.codec.truth(payload, self.tracker.layout)
                if tr is not None and tr[0] != key_id:
                    self._refuse(Reason.KEY_MISMATCH, key, f"truth of {tr[0]!r} on another target's key", kind=kind)
                    return None
                self._truth += 1
                if tr is not None:
                    self._truths.append(tr)
                return None
            elif kind == "input":
                c = self.codec.control(payload, arrival_ns)
                if c.source_id != key_id:
                    self._refuse(Reason.KEY_MISMATCH, key, f"an input of {c.source_id!r} on another source's key",
                                 kind=kind)
                    return None
                return c
            else:
                self._refuse(Reason.INVALID, key, "not a measurement, input or truth key", kind="other")
                return None
        except MalformedMessageError as e:
            self._refuse(Reason.MALFORMED, key, str(e), kind=kind)
            return None
        except UnsupportedVersionError as e:
            self._refuse(Reason.UNSUPPORTED_VERSION, key, str(e), kind=kind)
            return None
        except InvalidMessageError as e:
            self._refuse(Reason.INVALID, key, str(e), kind=kind)
            return None
        except Exception as e:  # a decoder bug must cost one sample, never the service
            log.exception("unexpected error decoding a sample on %s", key)
            self._refuse(Reason.MALFORMED, key, f"{type(e).__name__}: {e}", kind=kind)
            return None
        return self._checked(d, key, key_id, arrival_ns)

    def _checked(self, d: Detection, key: str, key_id: str, arrival_ns: int) -> Detection | None:
        """A decoded measurement on its key: refused (and counted) when it names another sensor
        or lies too far ahead of its arrival; else counted in the latency and gap statistics."""
        sensor, t_ns = d.sensor_id, d.t_ns
        if sensor != key_id:
            self._refuse(Reason.KEY_MISMATCH, key, f"a measurement of sensor {sensor!r} on another sensor's key", t_ns)
            return None
        if self.max_future_wall_ns is not None and t_ns > arrival_ns + self.max_future_wall_ns:
            self._refuse(Reason.FUTURE, key, f"sensor time {(t_ns - arrival_ns) / 1e9:.1f} s ahead of arrival", t_ns)
            return None
        pending = self._pending.get(sensor)
        if pending is None and sensor in self.tracker.sensors:
            pending = self._pending[sensor] = ([], [], [])
        if pending is not None:  # added to the statistics at the end of the batch, in this order
            pending[0].append(arrival_ns - t_ns)
            pending[1].append(d.epoch)  # ints, not (epoch, seq) tuples: nothing for the collector
            pending[2].append(d.seq)
        return d

    def _count_pending(self) -> None:
        """The latency and gap statistics of the batch's measurements (_checked), in order."""
        for sensor, (lat, epochs, seqs) in self._pending.items():
            self.latency.add_many(sensor, lat)
            self.gaps.add_many(sensor, epochs, seqs)
        self._pending.clear()

    def decoded(self, records: Sequence[Record]) -> list[Detection | None]:
        """Each record's measurement decoded in one loop (Codec.detections), None for the other
        kinds and where the loop could not convert a payload (ingest decodes those alone, with
        their errors): what `ingest(records, decoded=...)` takes. It changes nothing `ingest`
        counts, so a service decodes a burst's samples while the rest of it arrives."""
        routes = [self._route(key) for _, key, _ in records]
        try:
            fast = iter(self.codec.detections((r[0], r[2]) for r, rt in zip(records, routes, strict=True)
                                              if rt[0] == "meas"))
        except Exception as exc:  # a decoder bug: said, then each sample decoded alone (its errors are _decode's)
            self.warn.warn("batch_decode", "batch decode failed (%s: %s); decoding the batch's %d samples one by one",
                           type(exc).__name__, exc, len(records))
            return [None] * len(records)
        return [next(fast) if rt[0] == "meas" else None for rt in routes]

    def ingest(self, records: Sequence[Record], *, more: bool = False, prune: bool = True,
               decoded: Sequence[Detection | None] | None = None) -> Output:
        """Process samples in arrival order (after the measurements held from the last call); return
        the tracker's result and what to publish. With `more`, the batch's last scan waits for the
        next call (see the module docstring). With prune=False the caller calls `prune` itself,
        after publishing (the service: see `prune`). `decoded`: `decoded(records)`, if the caller
        made it (one item per record)."""
        dets: list[Detection | ControlInput] = list(self._held)
        self._held = []
        decode, checked, route = self._decode, self._checked, self._route
        if decoded is None:
            decoded = self.decoded(records)
        elif len(decoded) != len(records):
            raise ValueError(f"{len(decoded)} decoded measurements for {len(records)} records")
        self._received += len(records)
        try:
            for (arrival_ns, key, payload), d in zip(records, decoded, strict=True):
                d = decode(arrival_ns, key, payload) if d is None else checked(d, key, route(key)[1], arrival_ns)
                if d is not None:
                    dets.append(d)
        finally:
            self._count_pending()
            truths, self._truths = self._truths, []
            if truths and self.sink is not None:  # before the step, as each sample's call was
                self.sink.log_truths(truths)
        if more:
            self._held = _last_scan(dets)
            if self._held:
                del dets[len(dets) - len(self._held):]
        last_arrival = records[-1][0] if records else max((d.arrival_ns or 0 for d in dets), default=None)
        result = self.tracker.process(dets)
        for r in result.refused:
            self.warn.warn(r.reason.value, "refused %s#%d at t=%.3f s: %s: %s",
                           r.sensor_id, r.seq, r.t_ns / 1e9, r.reason.value, r.detail)
        if self.sink is not None and (result.estimates or result.events or result.refused or result.measurements):
            self.sink.log_step(result, arrival_ns=last_arrival)
        pub = self.view.select(result.estimates)
        events = self.view.select_events(result.events)
        if prune:
            self.prune()
        return Output(result, pub, events)

    def prune(self) -> None:
        """Forget the published estimates that can no longer be revised (PublishedView.prune: at
        most once per 250 ms of the horizon). It frees them, ~2 us each (~2 500 at 10k
        measurements/s), so the service calls it once a batch's estimates are out, not before; the
        next `ingest` sees the same view either way."""
        self.view.prune(self.tracker.horizon_ns, self.tracker.track_set)

    def snapshot(self) -> list[Estimate]:
        """The latest published estimate of every live confirmed track."""
        return self.view.snapshot(self.tracker.track_set)


def _last_scan(dets: list[Detection | ControlInput]) -> list[Detection]:
    """The measurements at the end of `dets` of the last one's scan (sensor_id, t_ns)."""
    if not dets or not isinstance(dets[-1], Detection):
        return []
    key = (dets[-1].sensor_id, dets[-1].t_ns)
    k = len(dets)
    while k and isinstance(dets[k - 1], Detection) and (dets[k - 1].sensor_id, dets[k - 1].t_ns) == key:  # type: ignore[union-attr]
        k -= 1
    return dets[k:]  # type: ignore[return-value]
