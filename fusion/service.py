"""The fusion service: Zenoh in, tracker, estimates out over Zenoh, every step to Rerun.

Threads: the subscribers hand their samples to Zenoh channels, and a thread per channel takes
them in chunks (fusion.io.channel_intake: one hand-over of the GIL per chunk, where a callback
cost one per sample) and only offers (arrival_ns, key, payload) to the intake queue
(fusion.io.intake_queue: a byte limit per message checked before the payload is copied, bounds
in samples and bytes, per-source rate limits and fair queueing, every refusal counted by reason)
and wakes the loop; the thread that calls `run` owns the tracker and does everything else, so
memory stays bounded. The loop drains batches that end where a burst of samples ends
(fusion.io.burst), so a sensor's scan is run once, whole.

Queryables (answers prepared by the loop, so callbacks never touch the tracker):
  fusion/<ns>/status     ServiceStatus (msgpack)
  fusion/<ns>/snapshot   the latest estimate of every confirmed track (msgpack list);
                         with ?t_ns=T every confirmed track predicted to T (answered by the loop;
                         fusion.snapshot_answers)
Publications (fusion.outbox): fusion/<ns>/tracks/<id> (estimates), fusion/<ns>/events/<id>
(confirmed, coasting, deleted with the reason, withdrawals; fusion.publication) and, with
[publication] period_s, fusion/<ns>/predicted (fusion.prediction); with smooth_lag,
fusion/<ns>/smoothed/<id> (fusion.fixed_lag).
Shutdown (SIGINT, SIGTERM or stop()): stop intake, drain the queue for at most
intake.drain_deadline_s (the rest dropped, counted as "shutdown"), flush and close the
recording and the stream file, close the Zenoh session.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from fusion.config import ServiceConfig, mode_names
from fusion.io import wire, zenoh_acl
from fusion.io.burst import Drained, drain_burst
from fusion.io.channel_intake import ChannelIntake, Taken
from fusion.io.checkpointer import Checkpointer, service_checkpoint_path
from fusion.io.gain_groups import measured_components
from fusion.io.intake_queue import IntakeLimits, IntakeQueue
from fusion.io.outputs import Outputs, open_outputs
from fusion.io.recording import RotatingSink
from fusion.io.recording_guard import GuardedSink
from fusion.io.rerun_sink import RerunSink
from fusion.io.sink_thread import SinkThread
from fusion.io.stream_rotation import RotatingStream
from fusion.io.zenoh_advanced import RecoveringSubscription
from fusion.io.zenoh_bus import Link, open_with_retry
from fusion.ledger import Ledger
from fusion.outbox import Outbox
from fusion.pipeline import Pipeline, Record
from fusion.snapshot_answers import SnapshotAnswers
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker
from fusion.tracking.trackset import Status
from fusion.tracking.warmup import warm_up

log = logging.getLogger("fusion.service")


class Service:
    """Build with a ServiceConfig, then `run()` until stopped. One instance, one thread."""

    def __init__(self, config: ServiceConfig, *, recording_dir: str | Path | None = None,
                 recording_path: str | Path | None = None, stream_path: str | Path | None = None) -> None:
        """recording_path: one file, no rotation (fusion demo); otherwise rotating files in
        recording_dir (default: the config's). stream_path: where the raw input goes (default:
        beside the first recording, when [recording] stream is on)."""
        import zenoh

        self._zenoh = zenoh
        self.config = config
        self.ns = config.namespace
        cp = service_checkpoint_path(config.checkpoint, config.recording, recording_dir=recording_dir,
                                     one_file=recording_path is not None)
        self.checkpoints = None if cp is None else Checkpointer(cp, interval_s=config.checkpoint.interval_s,
                                                                namespace=config.namespace)
        self.tracker = Tracker(config.tracker)  # the checkpoint's state, if any, is restored into it by open()
        self._where = (recording_dir, recording_path, stream_path)  # the files are created by open()
        self._out = Outputs(None, None, None, None)  # fusion.io.outputs
        self.pipeline = Pipeline(
            self.tracker, wire.Codec(self.ns), sink=None,
            max_future_wall_ns=round(config.intake.max_future_wall_s * 1e9),
            publish_tentative=config.publish_tentative, warnings_per_minute=config.warnings_per_minute,
        )
        ic = config.intake
        known = [s.id for s in config.tracker.sensors] + ([config.tracker.control.source_id]
                                                         if config.tracker.control is not None else [])
        self._q = IntakeQueue(IntakeLimits(queue_max=ic.queue_max, queue_max_bytes=ic.queue_max_bytes,
                                           max_message_bytes=ic.max_message_bytes, rate_hz=ic.source_rate_hz,
                                           burst=ic.source_burst), known=known)
        self.ledger = Ledger(self.pipeline, self._q)  # this run's counts (fusion.ledger)
        self._wake = threading.Event()
        self._channels: ChannelIntake | None = None  # the subscribers' channels, once open()
        self._stop = threading.Event()
        self._settled = 0  # samples fully handled (published, status refreshed) when the queue last emptied
        self._started_ns = time.time_ns()
        self._status_payload = b""
        self._status_at = 0.0
        self.snapshots = SnapshotAnswers(self.ns, self.tracker, self.pipeline.snapshot)
        self.session: Any = None
        self.outbox = Outbox(self.ns, self.tracker, self.snapshots, config.publication)  # fusion.outbox
        self._decls: list[Any] = []
        self._link = Link(config.zenoh)  # how the session is joined (fusion.io.zenoh_bus)

    @property
    def published(self) -> int:
        """Estimates published (the other kinds: `outbox`'s counts)."""
        return self.outbox.published

    @property
    def intake(self) -> IntakeQueue:
        """The intake queue (read its counts and depth; fusion.io.intake_queue)."""
        return self._q

    # ---- Zenoh side ----------------------------------------------------------------------------
    def _take(self, taken: Taken) -> None:
        """Samples from a subscriber's channel (fusion.io.channel_intake) into the intake queue;
        the loop woken if one was queued."""
        queued = self._q.offer_many([(arrival_ns, str(s.key_expr), len(p), p.to_bytes)
                                     for arrival_ns, s in taken for p in (s.payload,)])
        # Event.set takes the event's lock even when it is set (0.55 us against 0.03 for is_set);
        # a set event is safe to skip: the loop clears it only before its next drain, which takes
        # these samples (and marks itself busy first if samples wait)
        if queued and not self._wake.is_set():
            if self._writer is not None:
                self._writer.loop_busy()  # the recording's thread stops at its next pause (fusion.io.sink_thread)
            self._wake.set()

    def _on_status(self, query: Any) -> None:
        query.reply(wire.status_key(self.ns), self._status_payload)

    def _on_snapshot(self, query: Any) -> None:
        if self.snapshots.on_query(query):  # a ?t_ns query: the loop answers (fusion.snapshot_answers)
            self._wake.set()

    def _open_outputs(self) -> None:
        """Create the recording and the stream file (fusion.io.outputs; only once the session is
        open, so that a service that cannot start leaves no files behind)."""
        recording_dir, recording_path, stream_path = self._where
        tr = self.tracker
        self._out = open_outputs(
            self.config.recording, namespace=self.ns, recording_dir=recording_dir, recording_path=recording_path,
            stream_path=stream_path, counts=self.ledger.for_recording,
            sink_args={"layout": tr.layout, "position_indices": tr.position_indices,
                       "velocity_indices": tr.velocity_indices,
                       "meta": {"namespace": self.ns, "sensors": sorted(tr.sensors), "model": tr.model_name,
                                "modes": mode_names(self.config.tracker),
                                "measured": measured_components(tr.sensors, tr.layout)}})
        self.pipeline.sink = self._recording

    @property
    def sink(self) -> RotatingSink | RerunSink | None:
        """The recording (None when off)."""
        return self._out.sink

    @property
    def stream(self) -> RotatingStream | None:
        """The raw input's stream file (None when off)."""
        return self._out.stream

    @property
    def _writer(self) -> SinkThread | None:
        """The recording's thread ([recording] background), once started."""
        return self._out.writer

    @property
    def _recording(self) -> SinkThread | GuardedSink | None:
        """Where the pipeline and the loop send the recording's calls: its thread, or the guard."""
        return self._out.recording

    def _warm_up(self) -> None:
        """Before anything subscribes: the first call of a compiled kernel compiles it (about 20 s
        on the first run after an install, then loaded from numba's cache), which would otherwise
        fall on the first measurements and put the service that far behind its sensors."""
        t0 = time.perf_counter()
        ran = warm_up(self.config.tracker)
        took = time.perf_counter() - t0
        log.log(logging.WARNING if took > 5.0 else logging.INFO,
                "tracker kernels ready in %.1f s (%d synthetic measurements)%s", took, ran.detections,
                "; compiled on this first run after an install, cached for the next ones" if took > 5.0 else "")

    def _resume(self) -> None:
        """Restore a usable checkpoint into the tracker, in place (fusion.io.checkpointer)."""
        if self.checkpoints is not None and self.checkpoints.resume(self.tracker):
            self.ledger.resumed()

    def open(self) -> None:
        """Open the Zenoh session, compile the tracker's kernels (fusion.tracking.warmup), then
        the output files, then declare the subscribers and queryables. The session comes first so
        that a busy port fails at once, not after the seconds a first compile can take."""
        zc = self.config.zenoh
        self.session, self._link.connect_attempts = open_with_retry(zc, namespace=self.ns, stop=self._stop)
        if self.session is None:  # stopped while connecting: nothing was opened
            return
        try:
            self._warm_up()
            self._resume()
            self._open_outputs()
        except BaseException:
            self._out.close()
            self.session.close()
            self.session = None
            raise
        self.outbox.open(self.session)
        self._refresh_status(force=True)
        s = self.session
        fifo = self._zenoh.handlers.FifoChannel
        cap = self.config.intake.channel_capacity
        self._decls = [
            RecoveringSubscription(s, wire.all_measurements_key(self.ns), fifo(cap)),
            RecoveringSubscription(s, wire.all_input_key(self.ns), fifo(cap)),
            s.declare_subscriber(wire.all_truth_key(self.ns), fifo(cap)),
            s.declare_queryable(wire.status_key(self.ns), self._on_status),
            s.declare_queryable(wire.snapshot_key(self.ns), self._on_snapshot),
        ]
        self._channels = ChannelIntake([d.handler for d in self._decls[:3]], self._take)
        log.info("fusion service on namespace %r, zenoh %s %s", self.ns, zc.mode, zc.listen if zc.mode == "peer"
                 else zc.connect)
        for words in zenoh_acl.mismatches(zc.access_control, self.config.tracker):
            log.warning("access control: %s", words)

    # ---- the loop ------------------------------------------------------------------------------
    def stop(self) -> None:
        self._stop.set()
        self._wake.set()

    def _drain(self, limit: int) -> list[Record]:
        return self._q.drain(limit)

    def _drain_burst(self, limit: int) -> tuple[Drained, list[Detection | None]]:
        """A batch that takes the rest of a burst still arriving, and whether it was cut before
        the burst's end (fusion.io.burst); and its measurements, decoded part by part while the
        rest of the burst arrived (Pipeline.decoded)."""
        ic = self.config.intake
        decoded: list[Detection | None] = []
        drained = drain_burst(self._q, self._wake, limit, gap_s=ic.burst_gap_ms / 1e3,
                              linger_s=ic.burst_linger_ms / 1e3,
                              on_chunk=lambda chunk: decoded.extend(self.pipeline.decoded(chunk)))
        return drained, decoded

    def _holds_late(self, decoded: list[Detection | None]) -> bool:
        """Whether a batch holds a measurement of a scan before the tracker's newest (a replay)."""
        newest = self.tracker.newest_scan
        return newest is not None and any(d is not None and (d.t_ns, d.sensor_id) < newest for d in decoded)

    def _grow(self, batch: list[Record], decoded: list[Detection | None]) -> bool:
        """A full batch with late data and a backlog behind it, grown (in place, its decoded
        measurements with it) to up to intake.late_batch_max samples; whether samples are still
        queued after it (its last scan may then wait for its rest, as a cut batch's)."""
        more = self._drain(max(self.config.intake.late_batch_max - len(batch), 0))
        batch.extend(more)
        decoded.extend(self.pipeline.decoded(more))
        return bool(self._q)

    def _step(self, batch: list[Record], *, more: bool = False, decoded: list[Detection | None] | None = None) -> None:
        """One batch: to the stream file, through the pipeline (`more`: a backlog follows, so the
        batch's last scan waits for its rest: fusion.pipeline; `decoded`: its measurements, if
        decoded already), out to Zenoh; then the publication view pruned (Pipeline.prune: freeing
        what it forgets is no longer paid before publishing)."""
        if self.stream is not None:
            self.stream.write_many(batch)
        out = self.pipeline.ingest(batch, more=more, prune=False, decoded=decoded)  # pruned once out (below)
        self.ledger.took(len(batch))
        self.outbox.send(out)
        self.pipeline.prune()

    def run(self, *, duration_s: float | None = None) -> int:
        """Process until stop() (or a signal handler calling it) or `duration_s`; then shut down."""
        if self.session is None:
            self.open()
            if self.session is None:
                return 0
        deadline = None if duration_s is None else time.monotonic() + duration_s
        batch_max = self.config.intake.batch_max
        try:
            while not self._stop.is_set():
                if deadline is not None and time.monotonic() >= deadline:
                    break
                if self._writer is not None and self._q:
                    self._writer.loop_busy()  # the recording's thread waits for the loop's next pause
                (batch, cut), decoded = self._drain_burst(batch_max)
                if batch and cut and self._q and self._holds_late(decoded):
                    cut = self._grow(batch, decoded)  # one replay for the late data of more scans
                if batch:
                    self._step(batch, more=cut and bool(self._q), decoded=decoded)  # a cut burst's last scan waits
                    if not self._q:  # caught up: make the status answer current at once
                        self._refresh_status(force=True)
                        self._settled = self.ledger.handled
                else:
                    if self._writer is not None:
                        self._writer.loop_idle()
                    self._wake.wait(0.05)
                    self._wake.clear()
                    if not self._q and self._settled != self.ledger.handled:
                        self._refresh_status(force=True)  # samples refused at the door since the last batch
                        self._settled = self.ledger.handled
                self.snapshots.answer_waiting()
                if self._recording is not None:
                    self._recording.maybe_flush()
                    if batch and self._writer is not None and self._q:  # samples waited while it worked:
                        self._writer.behind()  # a backlog, where the loop may make the calls itself
                self._out.maybe_sweep()
                if self.checkpoints is not None:
                    self.checkpoints.maybe_write(self.tracker)
                self._refresh_status()
        finally:
            self.shutdown()
        return 0

    def shutdown(self) -> None:
        """Stop intake, drain, close the recording and the session (idempotent)."""
        if self.session is None:
            return
        for d in self._decls[:3]:  # subscribers: no more intake
            d.undeclare()
        if self._channels is not None and not self._channels.join():  # what their channels held, queued
            log.warning("shutdown: a Zenoh channel's intake thread did not end")
        deadline = time.monotonic() + self.config.intake.drain_deadline_s
        while self._q and time.monotonic() < deadline:
            self._step(self._drain(self.config.intake.batch_max))
        if self.pipeline.holding:  # a scan waiting for a rest that is not coming
            self._step([])
        left = self._drain(len(self._q)) if self._q else []
        if left:
            self.ledger.dropped(key for _, key, _ in left)
            log.warning("shutdown: drain deadline of %.1f s reached, %d queued samples dropped (counted as "
                        "'shutdown')", self.config.intake.drain_deadline_s, len(left))
            if self._recording is not None:  # a row to flush, so that the final counts reach the recording
                self._recording.log_text(0, f"shutdown: drain deadline reached, {len(left)} queued samples dropped",
                                     "WARN")
        if self.checkpoints is not None:
            self.checkpoints.write(self.tracker)
        self._refresh_status(force=True)
        self.snapshots.answer_waiting()
        for d in self._decls[3:]:
            d.undeclare()
        self._decls = []
        self.outbox.close()
        self._out.close()
        self.session.close()
        self.session = None
        log.info("fusion service stopped: %s", self.status_dict()["counts"])

    # ---- status --------------------------------------------------------------------------------
    def status_dict(self) -> dict[str, Any]:
        """The status (ServiceStatus): counts that add up (fusion.ledger), the tracks by status,
        latency, the recording, the queue, the sensors' gaps, the link to Zenoh, the checkpoints."""
        counts = np.bincount(self.tracker.track_set.status, minlength=len(Status)).tolist()  # not a Track per row
        by_status = {s.label: counts[s] for s in Status if counts[s]}
        return {
            "uptime_s": (time.time_ns() - self._started_ns) / 1e9,
            "counts": self.ledger.counts(published=self.published),
            "tracks": dict(sorted(by_status.items())),
            "latency": self.pipeline.latency.stats(),
            "recording": None if self.sink is None else str(self.sink.path),
            "recording_bytes": self._out.recording_bytes(),
            "queue_depth": len(self._q),
            "gaps": self._gaps(),
            "zenoh": self._link.report(self.session),
            "recording_error": self._out.error(),
            "recording_queue": 0 if self._writer is None else self._writer.queued_rows,
            "checkpoint": None if self.checkpoints is None else self.checkpoints.status(),
        }

    def _gaps(self) -> dict[str, dict[str, int]]:
        """Per sensor: seq values missing (and filled later), publisher runs (fusion.io.gaps),
        and samples zenoh reported missed for good (fusion.io.zenoh_advanced)."""
        out = {s: dataclasses.asdict(g) for s, g in self.pipeline.gaps.report().items()}
        for d in self._decls[:2]:
            for sensor, n in d.missed().items():
                row = out.setdefault(sensor, {"missing": 0, "filled": 0, "epochs": 0, "restarts": 0})
                row["zenoh_missed"] = row.get("zenoh_missed", 0) + n
        return dict(sorted(out.items()))

    def wait_idle(self, *, quiet_s: float = 0.3, timeout_s: float = 60.0) -> bool:
        """Wait (from another thread) until every sample that arrived is handled (estimates
        published, status answer current) and nothing new arrived for quiet_s."""
        deadline = time.monotonic() + timeout_s
        last, since = -1, time.monotonic()
        while time.monotonic() < deadline:
            n = self._q.offered
            if n != last or self._q:
                last, since = n, time.monotonic()
            elif time.monotonic() - since >= quiet_s and self._settled >= n and (
                    self._writer is None or self._writer.idle()):
                return True
            time.sleep(0.01)
        return False

    def _refresh_status(self, *, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._status_at < 0.1:
            return
        self._status_at = now
        self._status_payload = wire.encode_status(self.status_dict())
        self.outbox.retire(set(self.tracker.track_set.ids.tolist()))  # deleted tracks give their publishers back
        self.snapshots.refresh()
