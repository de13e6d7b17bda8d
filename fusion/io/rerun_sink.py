"""Every tracker step into a Rerun .rrd file, in columns, at a cost that does not grow with the
number of tracks.

Rerun costs ~0.1 ms or more per `send_columns` call here, whatever its size, so rows are buffered and
written with one call per entity (fusion.io.rerun_file writes them), and the number of entities is
bounded: the data of record are
three all-track entities (record/*: one row per estimate, association or event), scored every
`flush_interval_s` (checked on each step; each flush's share of the loop's time stays small) and
written every `write_interval_s` (the flush interval unless set), once an entity holds
`write_rows` rows (WRITE_ROWS), at `flush_rows` rows held and at `flush()`/`close()`: each chunk
written costs a row of the file's footer index, which Rerun holds in memory, dense over all of
the file's columns, until the file closes (fusion.io.allocator);
everything else (measured points, events as text, trails, truth, counts, OSPA/GOSPA, and the
first MAX_VIEWED confirmed tracks' own entities, chosen by the data (fusion.io.viewed): their
time series and cursor marks, ~15 each) is
written every `view_interval_s` (VIEW_INTERVAL_S, and at `flush()`/`close()`), or at the next
record flush once it holds `view_rows_max` rows (VIEW_ROWS_MAX: the all-track entities, the
estimates' and measurements' points and the events, at high rates; so a view flush never
converts 15 s of them at once, which was a +30-90 MB step of resident memory at 10k
measurements/s); a view flush writes the record at once and the views' entities VIEW_SLICE per
later call of maybe_flush (so the caller never waits for all ~130 at once; flush() and close()
write what still waits): a killed writer loses at most view_interval_s of them (and the few loop
calls the slices take), never more than
write_interval_s of the record. Rows are kept as numpy blocks per entity (fusion.io.columns)
and the viewed tracks' estimates as stacked arrays, so the per-track derivation runs once per
view flush; what is kept is bounded by the viewed tracks' rows and the drawn points, not by the
estimates' covariances.

Entity layout (positions in metres, world frame, 3-D points: 1-D tracks on the x axis, 2-D in the
z = 0 plane; track labels are fusion.io.labels.short_id of the id):
  record/estimates       every estimate and retraction: track, label, sensor, seq, status, revision,
                         x, std = sqrt(diag P), nis, nis_dof, nees, nees_dof, error, target (what
                         `fusion inspect` reads; NaN where a value does not apply)
  record/associations    every accepted measurement's association, and again whenever a replay changes it
                         (StepResult.associations): sensor, seq, outcome, track label, gated labels, nis
  record/truth           every true state logged: target, x (in the tracker's layout, float64)
  record/events          births, confirmations, coasting, deletions (with reason), withdrawals,
                         replays and refusals: kind, track, label, reason, retracted, detail
  events                 the same as human-readable lines (TextLog)
  world/estimates        confirmed estimates (trail), world/tentative: tentative ones (faint)
  world/meas/<sensor>    measured points, coloured by their association outcome
  world/truth            true positions
  world/tracks/<label>/{now,cov,start,end}  a viewed track at the cursor: labelled point, 2-sigma
                         ellipse (ellipsoid in 3-D), start and end markers; .../trail: earlier
                         2-sigma ellipses, faint, spaced apart (fusion.io.trail)
  tracks/<label>/...     a viewed track's time series (see fusion.io.blueprint.TRACK_VIEWS)
  metrics/{ospa,gospa}   set distances to truth (fusion.io.derive), counts/<name>: the tracker's counters
  meta                   static JSON: layout, position/velocity indices, sensors, run_id (one per
                         tracker run: the files of a rotated set share it; `fusion inspect` groups by it)
Timelines: `t` (sensor time: a duration from the stream's start, or a timestamp for epoch times),
`step` (tracker call counter), `arrival` (arrival time of the data that produced the row).
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.io import step_rows, track_rows, view_kernels
from fusion.io.columns import Column, stack
from fusion.io.derive import world
from fusion.io.labels import short_id
from fusion.io.palette import colour
from fusion.io.rerun_file import RerunFile
from fusion.io.viewed import FINAL
from fusion.tracking.results import Estimate, StepResult


def _no_pause() -> None:
    """A flush's parts back to back (no thread of its own to share the GIL with)."""


def _of_record(entity: str) -> bool:
    """Whether an entity is written at every record flush (record/*: the data of record), else
    at view flushes (everything drawn, the counts, the events as text)."""
    return entity.startswith("record/")


TRUTH_WAIT_NS = 2_000_000_000  # how long (arrival time) an estimate waits for its time's truth: RerunSink._flush
# The views are written every 15 s: writing an entity costs ~0.1-0.2 ms (~0.1-0.5 ms before its
# arrays were built here, fusion.io.arrow_columns) and the views are ~130 entities (6 tracks'
# series, counts, trails); every 5 s that was ~10 ms per second of CPU, ~10 us per measurement at
# 1000 measurements/s. The record is written every write_interval_s.
VIEW_INTERVAL_S = 15.0
# A record entity is written once it holds this many rows, before write_interval_s if need be:
# Rerun compresses chunks of up to ~5 000 estimate rows to ~176 bytes per row and larger ones to
# ~200 (measured on the shipped configuration at 667 targets; uncompressed 318 either way), so the
# fewer chunks of a longer interval would cost 10-20 % more bytes per measurement at 10k/s.
WRITE_ROWS = 4096
# An entity written at the view cadence goes out with the record once it holds this many rows:
# at 10k estimates/s, world/estimates every 2 s (one send_columns call, ~0.3 ms); the viewed
# tracks' own entities (a track's rows in 15 s) never get there.
VIEW_ROWS_MAX = 20_000
# A view flush's entities (~130: the viewed tracks' series, trails, counts, the all-track points)
# go out VIEW_SLICE per call of maybe_flush (one call per batch of the service's loop), not all in
# the flush itself: at 10k measurements/s sending them at once held the loop for 74-100 ms every
# view flush, and the scans behind it waited. The same rows and chunks; flush() and close() send
# what is still waiting.
VIEW_SLICE = 16


class RerunSink:
    """Buffers tracker output and writes it to `path` as a Rerun recording."""

    def __init__(
        self, path: str | Path, *, layout: tuple[str, ...], position_indices: tuple[int, ...],
        velocity_indices: tuple[int, ...], recording_id: str = "fusion", application_id: str = "fusion",
        flush_rows: int = 200_000, flush_interval_s: float = 0.2, write_interval_s: float | None = None,
        write_rows: int = WRITE_ROWS, flush_min_rows: int = 0,
        view_interval_s: float = VIEW_INTERVAL_S,
        view_rows_max: int = VIEW_ROWS_MAX, view_slice: int = VIEW_SLICE,
        meta: Mapping[str, Any] | None = None, counts: Callable[[], Mapping[str, int]] | None = None,
        run_id: str | None = None, pause: Callable[[], None] | None = None,
    ) -> None:
        self.run_id = run_id or uuid.uuid4().hex  # a new run unless continuing one (fusion.io.recording)
        view_kernels.warm()  # the view flushes' compiled loops, before any data
        info = {"layout": list(layout), "position_indices": list(position_indices),
                "velocity_indices": list(velocity_indices), "labels": "fusion.io.labels.short_id", **(meta or {}),
                "run_id": self.run_id}
        self.file = RerunFile(Path(path), recording_id=recording_id, application_id=application_id, meta=info)
        self.rows = track_rows.Rows(layout, list(position_indices), list(velocity_indices))
        self.ndim = len(position_indices)
        self._cols: dict[str, Column] = {}
        # estimates kept for scoring, as parallel lists: the estimate, its arrival (or t_ns), its step
        self._est: tuple[list[Estimate], list[int], list[int]] = ([], [], [])
        self._est_steps: list[tuple[tuple[Estimate, ...], int, int | None]] = []  # (estimates, step, arrival)
        self._steps: list[tuple[tuple, tuple, int, int | None]] = []  # (measurements, associations, step, arrival)
        self.flushes = 0  # flushes so far (fusion.io.recording looks at the file's size after each)
        self._truth_rows: list[tuple[list[int], int, Array, list[str]]] = []  # per log_truths: (t_ns, step, S, targets)
        self._scored: list[Any] = []  # the viewed tracks' rows (fusion.io.view_rows.Stacked) since the last view flush
        self._pending = 0
        self._flush_rows = flush_rows
        self._flush_min_rows = flush_min_rows
        self._interval = flush_interval_s
        self._write_interval = flush_interval_s if write_interval_s is None else write_interval_s
        self._write_rows = write_rows
        self._last_flush = self._last_view_flush = self._last_write = time.monotonic()
        self._view_interval = view_interval_s
        self._view_rows_max = view_rows_max
        self._view_slice = view_slice
        self._waiting: dict[str, Column] = {}  # a view flush's entities not sent yet (VIEW_SLICE per call)
        self._step = 0
        self._counts = counts
        # called between the parts of a flush: where the recording's thread may stop for the
        # service's loop (fusion.io.sink_thread.SinkThread.pause); nothing without one
        self._pause: Callable[[], None] = pause if pause is not None else _no_pause
        self._counts_written: list[tuple[str, int]] = []  # the counts of the last counts rows
        self._newest_t = 0
        self._newest_arr = -(2**63)  # the newest arrival (or sensor time) of the estimates logged
        self._horizon_ns: int | None = None  # the newest StepResult.horizon_ns: rows before it are final
        self._closed = False
        # the names of an IMM's modes for their probability series (meta "modes"; else "mode j")
        self.mode_names: tuple[str, ...] = tuple(str(n) for n in (meta or {}).get("modes", ()))
        # each sensor's measured components as (name, unit), to split the gain by unit (meta
        # "measured", fusion.io.gain_groups.measured_components; else one unsplit gain view)
        self.measured: dict[str, list[list[list[str]]]] = dict((meta or {}).get("measured", {}))
        # the layout is first sent with the first rows written (or at close): one blueprint less per
        # file (~20 ms of rerun's blueprint building each); a file with no rows has nothing to lay out

    # ---- continuity across files -----------------------------------------------------------------
    def continue_from(self, previous: RerunSink) -> None:
        """Carry what spans files over from the sink of the previous file of a rotated set: the
        truth kept for scoring, the viewed tracks, and the kind of the time axes."""
        self.rows.continue_from(previous.rows)
        self.file.epoch, self.file.arrival_epoch = previous.file.epoch, previous.file.arrival_epoch
        self._step = previous.steps()

    @property
    def path(self) -> Path:
        """The .rrd file written."""
        return self.file.path

    @property
    def rec(self) -> Any:
        """The file's Rerun stream (for what is logged beside the sink's rows: fusion.io.smoothed)."""
        return self.file.rec

    @property
    def epoch_time(self) -> bool | None:
        """Whether the `t` timeline holds epoch timestamps (True) or durations from the stream's
        start (False); None until the first rows are written. Anything else logged on `t`
        (fusion.io.smoothed) must use the same kind: Rerun keeps one type per timeline."""
        return self.file.epoch

    @property
    def rows_written(self) -> int:
        """Rows written to the file so far (fusion.io.rerun_file)."""
        return self.file.rows_written

    def steps(self) -> int:
        """Tracker steps logged so far (continued across a rotated set)."""
        return self._step

    # ---- input -----------------------------------------------------------------------------------
    def col(self, entity: str, kind: str, **style: Any) -> Column:
        """The pending Column of `entity` (created with its kind and style on first use)."""
        c = self._cols.get(entity)
        if c is None:
            c = self._cols[entity] = Column(kind, **style)
        return c

    def log_truths(self, truths: Sequence[tuple[str, int, Array]]) -> None:
        """True states in the tracker's layout, (target_id, t_ns, state) each; kept to score
        estimates at the same t_ns (fusion.io.truth_table), and as one block of rows for the
        record/truth and world/truth rows written at the next flush. One call for a batch's truth:
        a call per sample through the sink's wrappers was ~10 % of the recording's time at 10
        targets fed fast (a line profile: bench/HISTORY.md, Recording)."""
        if not truths:
            return
        targets, t_ns, states = (list(c) for c in zip(*truths, strict=True))  # one pass
        S = stack(states)  # float64: the states as logged
        self.rows.add_truths(targets, t_ns, S)
        self._truth_rows.append((t_ns, self._step, S, targets))
        self._pending += len(targets)

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        """A line for the events view, and a structured "note" event beside it."""
        self._event(t_ns, "note", None, "", False, text, level)

    def _event(self, t_ns: int, kind: str, track_id: int | None, reason: str, retracted: bool, text: str,
               level: str = "INFO") -> None:
        self.col("events", "text").add(t_ns, self._step, t_ns, text=text, level=level)
        self.col("record/events", "record").add(
            t_ns, self._step, t_ns, kind=kind, track=-1 if track_id is None else int(track_id),
            label="" if track_id is None else short_id(track_id), reason=reason, retracted=retracted, detail=text)
        self._pending += 2

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        """One Tracker.process result: measurements and their associations, estimates, events,
        replays and refusals. The result's measurements, associations and estimates are kept as
        they are (a few Python operations per step, whatever their number) and turned into rows
        at the next flush, for all the steps since the last one at once (`_rows_of_steps`)."""
        self._step += 1
        step = self._step
        h = result.horizon_ns
        if h is not None and (self._horizon_ns is None or h > self._horizon_ns):
            self._horizon_ns = h
        ms, A, E = result.measurements, result.associations, result.estimates
        if ms or A:
            self._steps.append((ms, A, step, arrival_ns))
            # the rows they will make, as counted towards flush_rows: one per scan, one per association
            self._pending += len(ms) + result.n_associations
        if E:
            self._est_steps.append((E, step, arrival_ns))
            self._pending += len(E)
        for ev in result.events:
            why = "" if ev.reason is None else ev.reason.value
            text = f"track {short_id(ev.track_id)} " + ("withdrawn " if ev.retracted else "") + ev.kind.value
            text += (f" ({why})" if why else "") + (" (gone after a replay)" if ev.retracted else "")
            self._event(ev.t_ns, ev.kind.value, ev.track_id, why, ev.retracted, text)
        for rp in result.replays:
            late = ", ".join(f"{s}#{q}" for s, q in rp.trigger)
            self._event(rp.from_t_ns, "replay", None, "", False, f"replay of {rp.n_scans} scans from late {late}",
                        "WARN")
        for r in result.refused:
            self._event(r.t_ns, "refused", None, r.reason.value, False,
                        f"refused {r.sensor_id}#{r.seq}: {r.reason.value}: {r.detail}", "WARN")
        self.maybe_flush()

    def _rows_of_steps(self) -> None:
        """The rows of the steps logged since the last flush: the associations and measured
        points (fusion.io.step_rows), and the estimates kept for scoring (self._est: estimates,
        arrivals (or their t_ns), steps)."""
        kept_E, kept_arr, kept_step = self._est
        for E, step, arrival_ns in self._est_steps:
            kept_E.extend(E)
            kept_step.extend([step] * len(E))
            arr = [e.t_ns for e in E] if arrival_ns is None else [arrival_ns] * len(E)
            kept_arr.extend(arr)
            self._newest_arr = max(self._newest_arr, max(arr) if arrival_ns is None else arrival_ns)
        self._est_steps = []
        steps, self._steps = self._steps, []
        if not steps:
            return
        step_rows.associations(steps, self)
        step_rows.measured_points(steps, self)

    # ---- writing ---------------------------------------------------------------------------------
    def maybe_flush(self) -> None:
        """The record on its cadence, the views on theirs (view_interval_s). The record is scored
        once flush_rows rows wait; every flush_interval_s once flush_min_rows wait; and every
        write_interval_s whatever waits (its rows are scored before they are written). A flush
        has a fixed cost (~0.8 ms at 10 targets: the counts, the scoring's and the writing's
        calls, whatever the rows), which a few rows every flush_interval_s would pay again and
        again: at 10 targets in real time (150 measurements/s) 0.2 s holds ~30 measurements. The
        default here, 0, scores every flush_interval_s; the service's is
        fusion.config.RecordingConfig.flush_min_rows."""
        now = time.monotonic()
        since = now - self._last_flush
        if (self._pending >= self._flush_rows or since >= self._write_interval
                or (since >= self._interval and self._pending >= self._flush_min_rows)):
            self._flush(views=now - self._last_view_flush >= self._view_interval, final=False)
        elif self._waiting:
            self._send({k: self._waiting.pop(k) for k in sorted(self._waiting)[:self._view_slice]})

    @property
    def waiting(self) -> int:
        """Entities of the last view flush not written yet (maybe_flush writes VIEW_SLICE per call)."""
        return len(self._waiting)

    def flush(self) -> None:
        """Derive the rows of the kept estimates and write every pending row as columns."""
        self._flush(views=True, final=True)

    def _flush(self, *, views: bool, final: bool, ends: bool = False) -> None:
        """Write the record's rows, and the views' rows too when `views` (with the viewed tracks'
        end markers when `ends`). Unless `final`, estimates at or after the newest truth time wait
        for the next flush, for at most TRUTH_WAIT_NS of arrival time (sensor time where arrivals
        are unknown) after the newest arrival: truth arrives in time order, but may come after the
        measurements of the same time, and the truth of a time is complete only once a later
        time's has come (scoring against part of it would match another target, and what is
        scored would depend on when the flush fell). The bound is on arrival time, not on how far
        the estimates' sensor time runs ahead of the truth's: a simulation sent faster than real
        time (`fusion demo --speed max`) brings seconds of sensor time in a fraction of a second,
        and its truth, over another link, could fall that far behind its measurements.

        The record (record/*: what `fusion inspect` scores) is scored and written at every call;
        the rows of everything else (measured points, events as text, trails, truth, OSPA/GOSPA,
        counts) are kept as column chunks and the viewed tracks' estimates as stacked arrays,
        derived and written at view flushes only: Rerun's per-entity cost and the per-track
        derivation are paid once per view_interval_s."""
        self._rows_of_steps()
        self._pause()
        E, arr, stp = self._est
        self._est = ([], [], [])
        t_est = np.fromiter((e.t_ns for e in E), dtype=np.int64, count=len(E))
        arr_e, stp_e = np.array(arr, dtype=np.int64), np.array(stp, dtype=np.int64)
        if len(E):
            self._newest_t = max(self._newest_t, int(t_est.max()))
        newest = self.rows.newest_truth_ns
        if not final and newest is not None and len(E):
            wait = (t_est >= newest) & (arr_e >= self._newest_arr - TRUTH_WAIT_NS)
            if wait.any():
                w = wait.tolist()
                self._est = ([e for e, k in zip(E, w, strict=True) if k], arr_e[wait].tolist(), stp_e[wait].tolist())
                E = [e for e, k in zip(E, w, strict=True) if not k]
                t_est, arr_e, stp_e = t_est[~wait], arr_e[~wait], stp_e[~wait]
        truth, self._truth_rows = self._truth_rows, []
        if truth:
            t_t = [t for b in truth for t in b[0]]
            step_t = [b[1] for b in truth for _ in b[0]]
            S = np.concatenate([b[2] for b in truth])  # the states as logged: float64
            targets = [x for b in truth for x in b[3]]
            self.col("record/truth", "record").extend(t_t, step_t, t_t, blocks={"x": S},
                                                      target=targets)  # float64: for inspect
            W = world(S[:, self.rows.pi])
            self.col("world/truth", "points", rgba=colour("truth"), radius=-1.5).extend(
                t_t, step_t, t_t, p=W[:, None, :])
        waiting = min(e.t_ns for e in self._est[0]) if self._est[0] else None  # the oldest row waiting
        horizon = FINAL if ends else self._horizon_ns
        if horizon is not None and waiting is not None:  # rows waiting for the next flush are not final either
            horizon = min(horizon, waiting)
        scored = self.rows.score(E, t_est, arr_e, stp_e, self, horizon_ns=horizon)
        if scored is not None:
            self._scored.append(scored)
        if self._horizon_ns is not None:  # every estimate still to score is at or after it
            self.rows.forget_truth_before(self._horizon_ns if waiting is None else min(self._horizon_ns, waiting))
        self._pause()
        if self._counts is not None and (self._pending or final):
            counts = sorted(self._counts().items())
            if self._pending or counts != self._counts_written:  # the final counts always reach the file
                for name, v in counts:
                    self.col(f"counts/{name}", "scalars", width=1).add(self._newest_t, self._step, self._newest_t,
                                                                       v=[v])
                self._counts_written = counts
        write = views  # a view flush writes everything; otherwise the record on its own cadence
        if views:
            batches, self._scored = self._scored, []
            self.rows.views(batches, self, pause=self._pause)
            if ends:
                self.rows.mark_ends(self)
            self._send(self._waiting)  # what the last view flush left goes out before the new rows
            self._waiting = {}
            cols, self._cols = self._cols, {}
            if not final:  # the record now, the views' entities VIEW_SLICE per maybe_flush
                later = sorted(k for k in cols if not _of_record(k))[self._view_slice:]
                self._waiting = {k: cols.pop(k) for k in later}
            self._last_view_flush = time.monotonic()
        else:
            held = [len(c) for k, c in self._cols.items() if _of_record(k)]
            write = (sum(held) >= self._flush_rows or max(held, default=0) >= self._write_rows
                     or time.monotonic() - self._last_write >= self._write_interval)
            due = [k for k, c in self._cols.items() if (write and _of_record(k)) or len(c) >= self._view_rows_max]
            cols = {k: self._cols.pop(k) for k in due}
        if write:
            self._last_write = time.monotonic()
        self._send(cols)
        self._pending = 0
        self.flushes += 1
        if views and not self._waiting:
            self._send_blueprint()
        self._last_flush = time.monotonic()

    def _send(self, cols: dict[str, Column]) -> None:
        """The entities' rows to the file (fusion.io.rerun_file), the layout again once an entity
        is written for the first time and the view flush is all out."""
        if self.file.send(cols, self._pause) and not self._waiting:
            self._send_blueprint()

    def _send_blueprint(self) -> None:
        """The layout of the viewed tracks and of the views holding data (sent when it changed)."""
        centre, extent = self.rows.scene()
        self.file.send_layout(ndim=self.ndim, axes=self.rows.axes, viewed=self.rows.viewed_labels(), centre=centre,
                              extent_m=extent)

    def close(self) -> None:
        """Flush everything, mark where viewed tracks end, and finish the file (complete footer)."""
        if self._closed:
            return
        self._flush(views=True, final=True, ends=True)
        self.file.close()
        self._closed = True

    def __enter__(self) -> RerunSink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
