"""The recording on a thread of its own: the service's loop hands each call over and goes on.

Every call the pipeline and the loop make on the recording (log_step, log_truths, log_text,
maybe_flush, close) is queued, in order, for one writer thread that makes it on the sink
(fusion.io.recording_guard.GuardedSink over a RerunSink or a RotatingSink): the sink sees the
same calls in the same order as when the loop made them itself, so the file holds the same rows;
what changes is who waits. The record flush (scoring, step rows, Rerun's columns: ~24 ms every
0.2 s at 10k measurements/s, bench/HISTORY.md) and the view flush no longer stop the loop.

The two threads share the GIL, so a flush running while the loop handles a scan would slow the
scan down as much as it did on the loop: the writer waits while the loop is busy (`loop_busy()`
when samples are queued, `loop_idle()` when the loop is about to wait for more), before each call,
for at most `max_defer_s` in all per round of the calls it takes, so its work falls in the gaps
between scans; Rerun's encoding and file writing release the GIL, so part of it runs on the
other core whenever it runs. A loop that is never
idle (a backlog: samples wait for it when it ends a batch) makes the calls itself: at its
`behind()`, once the oldest call waiting was queued max_defer_s ago, it takes them all and makes
them on its own thread, as a recording on the loop would, while the writer waits for it (`turns`
counts these). The two threads taking turns with the GIL cost the loop more than the calls
themselves: in a blast at 100 targets the service applied 32-33k measurements/s with the writer
making them and 36-37k with the loop making them (`[recording] background = false`;
bench/HISTORY.md). A loop that keeps up (samples arrive while it works, but none wait when it ends
a batch) leaves them to the writer: a record flush made between two scans would delay the next.
The writer goes on by itself if the loop has not taken them within another max_defer_s (a loop
that does not call behind()). A flush is one call but
many parts (scoring, the views' derivation, one send per entity: 20-70 ms in all at 10k
measurements/s, longer than the ~25 ms between two scans), so the sink also stops at `pause()`
between its parts (fusion.io.rerun_sink), within the same budget; and the loop's intake marks
the loop busy as samples arrive (`loop_busy()` from the intake's thread, fusion.io.channel_intake),
not only when the loop next looks: a flush that ran on while a scan's burst came in held the GIL from the
callbacks, the burst came in slowly, the loop took it in two batches and ran the scan twice.

Bounded: at most `max_rows` rows (estimates, associations, truth samples, texts) wait in the
queue; a loop that gets that far ahead waits for the writer (counted in `waits`), so nothing is
dropped and memory stays bounded. The counts the recording writes (its `counts/*` series) are
the loop's, taken at most every `counts_every_s` and at close and queued with the calls, so the
writer writes counts as of a step it has already logged (`counts()`, the sink's counts callback).
The loop's own maybe_flush (between batches, and every 50 ms when idle) is queued like the rest,
so the file keeps its cadence when no sample comes, and the sink sees exactly the calls it saw
when the loop made them.

Errors: the guard turns the sink's OSError and RuntimeError into a stopped recording (its
`error`), as before; any other exception (a bug) stops the writer and is raised again on the
loop's thread at its next call (at once from behind() when the loop made the call), as it would
have been raised there before. `close()` queues the close, waits for the writer to finish it and
raises what it raised.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fusion.io.recording_guard import GuardedSink
from fusion.tracking.results import StepResult

MAX_ROWS = 50_000  # ~2.5 s of rows at 10k measurements/s (an estimate and an association each)
COUNTS_EVERY_S = 0.1  # the loop's counts, taken at most this often (half the record's flush interval)
MAX_DEFER_S = 0.25  # the longest the writer waits for the loop to go idle


class SinkThread:
    """See the module docstring. Build, give the sink `counts=writer.counts`, then `start(guard)`."""

    def __init__(self, *, counts: Callable[[], Mapping[str, int]] | None = None, max_rows: int = MAX_ROWS,
                 counts_every_s: float = COUNTS_EVERY_S, max_defer_s: float = MAX_DEFER_S) -> None:
        self._source = counts
        self._max_rows = max_rows
        self._counts_every_s = counts_every_s
        self._max_defer_s = max_defer_s
        self._loop_idle = threading.Event()
        self._loop_idle.set()
        self._counts: Mapping[str, int] = {}  # the writer's: as of the last call it made
        self._counts_at = -float("inf")
        self._cv = threading.Condition(threading.Lock())
        self._calls: deque[tuple[int, Callable[..., None], tuple, dict[str, Any]]] = deque()
        self._held = 0  # rows queued or under way
        self._taken = 0  # calls taken by the writer and not made yet
        self._failure: BaseException | None = None
        self._closing = False
        self._thread: threading.Thread | None = None
        self._defer_until = 0.0  # the end of this round's budget of waiting for the loop
        self._making = threading.Lock()  # held by whoever makes calls: the writer, or the loop in a backlog
        self._queued_at: float | None = None  # when the oldest call waiting was queued
        self.turns = 0  # times the loop made the calls itself (a backlog: behind())
        self._guard: GuardedSink | None = None
        self.waits = 0  # times the loop waited for room in the queue
        self.calls = 0  # calls made on the sink

    # ---- the loop's side ---------------------------------------------------------------------------
    def start(self, guard: GuardedSink) -> None:
        self._guard = guard
        self._thread = threading.Thread(target=self._run, name="fusion-recording", daemon=True)
        self._thread.start()

    @property
    def path(self) -> Path:
        return self._guard.path  # type: ignore[union-attr]

    @property
    def error(self) -> str | None:
        """Why the recording stopped (the guard's), None while it records."""
        return None if self._guard is None else self._guard.error

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        rows = len(result.estimates) + result.n_associations + len(result.events) + len(result.refused) + 1
        self._put(rows, self._guard.log_step, (result,), {"arrival_ns": arrival_ns})  # type: ignore[union-attr]

    def log_truths(self, truths: Sequence[tuple[str, int, np.ndarray]]) -> None:
        """A batch's truth samples, one call queued (the caller does not change the list after)."""
        self._put(len(truths), self._guard.log_truths, (truths,))  # type: ignore[union-attr]

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        self._put(1, self._guard.log_text, (t_ns, text, level))  # type: ignore[union-attr]

    def maybe_flush(self) -> None:
        """The loop's call between batches (the sink's cadence: fusion.io.rerun_sink), queued."""
        self._put(0, self._guard.maybe_flush, ())  # type: ignore[union-attr]

    def behind(self) -> None:
        """The loop's call between two batches when samples are already waiting for it (a
        backlog: it has no pause to leave to the writer): once the oldest call waiting was queued
        max_defer_s ago, the loop makes the calls waiting itself, here, on its own thread."""
        since = self._queued_at
        if since is None or time.monotonic() - since < self._max_defer_s or not self._making.acquire(blocking=False):
            return
        try:
            self.turns += 1
            self._make_waiting(on_writer=False)
        finally:
            self._making.release()
        self._raise_failure()

    def loop_busy(self) -> None:
        """The loop has samples to handle (the loop, or the intake as one arrives): the writer
        waits (at most max_defer_s per round), before its next call or at its next pause()."""
        if self._loop_idle.is_set():
            self._loop_idle.clear()

    def loop_idle(self) -> None:
        """The loop is about to wait for samples: the writer's turn."""
        if not self._loop_idle.is_set():
            self._loop_idle.set()

    @property
    def queued_rows(self) -> int:
        """Rows handed over and not written yet (the service's status)."""
        return self._held

    def idle(self) -> bool:
        """Nothing queued and no call under way."""
        with self._cv:
            return not self._calls and not self._taken

    def close(self) -> None:
        """Queue the close (with the final counts), wait for the writer to make it; raise what the
        writer raised."""
        if self._thread is None:
            return
        self.loop_idle()
        if self._thread.is_alive():
            self._take_counts()
            self._put(0, self._close, ())
            self._thread.join()
        self._thread = None
        self._raise_failure()

    def _put(self, rows: int, call: Callable[..., None], args: tuple, kw: dict[str, Any] | None = None) -> None:
        self._raise_failure()
        if self._source is not None and time.monotonic() - self._counts_at >= self._counts_every_s:
            self._take_counts()
        self._enqueue(rows, call, args, kw or {})

    def _take_counts(self) -> None:
        """The loop's counts now, queued: as of the calls queued before (the sink writes them
        when it flushes after those calls)."""
        if self._source is None:
            return
        self._counts_at = time.monotonic()
        self._enqueue(0, self._set_counts, (dict(self._source()),), {})

    def _enqueue(self, rows: int, call: Callable[..., None], args: tuple, kw: dict[str, Any]) -> None:
        with self._cv:
            while self._held and self._held + rows > self._max_rows and self._failure is None:
                self.waits += 1
                self.loop_idle()  # the loop waits: the writer's turn
                self._cv.wait(0.5)
            self._held += rows
            self._calls.append((rows, call, args, kw))
            if len(self._calls) == 1:
                self._queued_at = time.monotonic()
                self._cv.notify_all()
        self._raise_failure()

    def _raise_failure(self) -> None:
        if self._failure is not None:
            raise self._failure

    # ---- the writer's side -------------------------------------------------------------------------
    def pause(self) -> None:
        """A point inside a call where the writer may stop for the loop (the sink calls it between
        the parts of a flush): while the loop is busy, wait for it, within this round's budget.
        A no-op on any other thread than the writer's."""
        if threading.current_thread() is not self._thread or self._loop_idle.is_set():
            return
        left = self._defer_until - time.monotonic()
        if left > 0:
            self._loop_idle.wait(left)

    def counts(self) -> Mapping[str, int]:
        """The sink's counts callback (called on the writer's thread): as of the last call made."""
        return self._counts

    def _set_counts(self, snapshot: Mapping[str, int]) -> None:
        self._counts = snapshot

    def _close(self) -> None:
        self._closing = True
        self._guard.close()  # type: ignore[union-attr]

    def _make_waiting(self, *, on_writer: bool) -> None:
        """Make the calls waiting, in order (the caller holds _making). On the writer's thread it
        stops at pause() before each; a call that raises stops the recording's thread (`_failure`)."""
        with self._cv:
            calls = list(self._calls)
            self._calls.clear()
            self._taken = len(calls)
            self._queued_at = None
        try:
            for rows, call, args, kw in calls:
                if on_writer:
                    self.pause()  # the loop got busy meanwhile: wait again, within the budget
                call(*args, **kw)
                self.calls += 1
                with self._cv:
                    self._held -= rows
                    self._taken -= 1
                    self._cv.notify_all()
                if self._closing:
                    break
        except BaseException as e:  # a bug in the recording: raised again on the loop's thread
            self._failure = e
            self._closing = True
            with self._cv:
                self._calls.clear()
                self._held = self._taken = 0
                self._cv.notify_all()

    def _run(self) -> None:
        while not self._closing:
            with self._cv:
                if not self._calls:
                    self._cv.wait(0.5)
                    continue
            self._defer_until = time.monotonic() + self._max_defer_s  # this round's budget
            if not self._loop_idle.wait(self._max_defer_s):
                # the loop may be in a backlog: then it makes the calls itself at its next behind()
                # (two threads taking turns with the GIL cost it more than the calls); the writer
                # goes on if it does not within another max_defer_s, or once the loop is idle
                end, turns = time.monotonic() + self._max_defer_s, self.turns
                with self._cv:
                    while self.turns == turns and not self._loop_idle.is_set() and (left := end - time.monotonic()) > 0:
                        self._cv.wait(min(left, 0.02))
                if self.turns != turns:  # the loop made them: what it queued since is a new round
                    continue
            with self._making:
                self._make_waiting(on_writer=True)
