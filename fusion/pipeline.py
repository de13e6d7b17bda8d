"""The one path every sample takes, live or replayed: decode, validate, track, record.

`Pipeline.ingest(records)` takes raw samples `(arrival_ns, key, payload)` in arrival order and
returns the estimates to publish. The live service feeds it batches drained from its intake
queue; `fusion replay` feeds it the same records read back from a stream file. The tracker's
result depends only on the measurements accepted, and acceptance is decided one sample at a
time in arrival order, so a replay reproduces the live run's estimates exactly, however the
records are batched.

Counts add up: received = applied + duplicates + sum(refused by reason) (+ queued, in the service).
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from fusion.io.latency import LatencyTracker
from fusion.io.ratelimit import RateLimitedLog
from fusion.tracking.detection import Detection, Reason
from fusion.tracking.results import Estimate, StepResult
from fusion.tracking.tracker import Tracker

log = logging.getLogger("fusion.pipeline")

Record = tuple[int, str, bytes]  # (arrival_ns, key expression, payload)


class BadSample(Exception):  # noqa: N818 - a refusal, not a failure
    """A sample refused at the edge, with its reason."""

    def __init__(self, reason: Reason, detail: str) -> None:
        super().__init__(f"{reason.value}: {detail}")
        self.reason = reason
        self.detail = detail


class Codec(Protocol):
    """Wire decoding the pipeline needs (fusion.io.wire implements it)."""

    def kind(self, key: str) -> str:
        """"meas", "truth" or "other" for a key expression."""
        ...

    def detection(self, payload: bytes) -> Detection:
        """A Detection, or BadSample(MALFORMED | INVALID | BAD_COVARIANCE, why)."""
        ...

    def truth(self, payload: bytes, layout: tuple[str, ...]) -> tuple[str, int, np.ndarray] | None:
        """(target_id, t_ns, state in `layout`), None when the truth lacks a component; BadSample if malformed."""
        ...


class Sink(Protocol):
    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None: ...

    def log_truth(self, target_id: str, t_ns: int, state: np.ndarray) -> None: ...

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None: ...


@dataclass(frozen=True)
class Output:
    result: StepResult
    to_publish: tuple[Estimate, ...]


class Pipeline:
    """Decode, validate, track and record; see the module docstring."""

    def __init__(self, tracker: Tracker, codec: Codec, *, sink: Sink | None = None,
                 max_future_wall_ns: int | None = None, publish_tentative: bool = False,
                 warnings_per_minute: int = 60) -> None:
        self.tracker = tracker
        self.codec = codec
        self.sink = sink
        self.max_future_wall_ns = max_future_wall_ns
        self.publish_tentative = publish_tentative
        self.counts: Counter[str] = Counter()
        self.latency = LatencyTracker()
        self.warn = RateLimitedLog(log, per_minute=warnings_per_minute)
        self.truth_samples = 0

    def _refuse(self, reason: Reason, key: str, detail: str, t_ns: int = 0) -> None:
        self.counts[f"refused_{reason.value}"] += 1
        self.warn.warn(reason.value, "refused sample on %s: %s: %s", key, reason.value, detail)
        if self.sink is not None:
            self.sink.log_text(t_ns, f"refused sample on {key}: {reason.value}: {detail}", "WARN")

    def ingest(self, records: Sequence[Record]) -> Output:
        """Process samples in arrival order; return the tracker's result and what to publish."""
        dets: list[Detection] = []
        last_arrival = None
        for arrival_ns, key, payload in records:
            last_arrival = arrival_ns
            kind = self.codec.kind(key)
            if kind == "truth":
                self.counts["truth"] += 1
                try:
                    tr = self.codec.truth(payload, self.tracker.layout)
                except BadSample as e:
                    self._refuse(e.reason, key, e.detail)
                    continue
                if tr is not None and self.sink is not None:
                    self.sink.log_truth(*tr)
                continue
            self.counts["received"] += 1
            if kind != "meas":
                self._refuse(Reason.INVALID, key, "not a measurement key")
                continue
            try:
                d = self.codec.detection(payload)
            except BadSample as e:
                self._refuse(e.reason, key, e.detail)
                continue
            except Exception as e:  # a decoder bug must cost one sample, never the service
                log.exception("unexpected error decoding a sample on %s", key)
                self._refuse(Reason.MALFORMED, key, f"{type(e).__name__}: {e}")
                continue
            if self.max_future_wall_ns is not None and d.t_ns > arrival_ns + self.max_future_wall_ns:
                self._refuse(Reason.FUTURE, key, f"sensor time {(d.t_ns - arrival_ns) / 1e9:.1f} s ahead of arrival",
                             d.t_ns)
                continue
            if d.sensor_id in self.tracker.sensors:
                self.latency.add(d.sensor_id, arrival_ns - d.t_ns)
            dets.append(d)
        result = self.tracker.process(dets)
        self.counts["applied"] += result.applied
        for r in result.refused:
            if r.reason == Reason.DUPLICATE:
                self.counts["duplicates"] += 1
            else:
                self.counts[f"refused_{r.reason.value}"] += 1
            self.warn.warn(r.reason.value, "refused %s#%d at t_ns=%d: %s: %s",
                           r.sensor_id, r.seq, r.t_ns, r.reason.value, r.detail)
        if self.sink is not None and (result.estimates or result.events or result.refused or result.measurements):
            self.sink.log_step(result, arrival_ns=last_arrival)
        pub = tuple(e for e in result.estimates if e.status != "tentative" or self.publish_tentative)
        return Output(result, pub)

    def refused_by_reason(self) -> dict[str, int]:
        return {k[len("refused_"):]: v for k, v in sorted(self.counts.items()) if k.startswith("refused_")}
