"""The recording's thread (fusion.io.sink_thread): the sink gets the same calls in the same order
(a recording through it has the digest of one written on the loop), the loop waits only when
max_rows rows are queued and loses none, the writer waits while the loop is busy, a loop behind
(a backlog) makes the calls that waited max_defer_s itself and the writer goes on by itself
after twice that, a bug in the recording is raised on the loop's thread, a failing file
stops the recording and nothing else, and the counts it writes are those of the calls it has
made."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import pytest

from fusion.io.recording_guard import GuardedSink
from fusion.io.sink_thread import SinkThread
from fusion.tracking.results import StepResult
from tests.io.recording_digest import digest
from tests.io.scenario_run import maneuver_run, record_scenario


class FakeSink:
    """Notes every call (name, args, the counts the sink would write, wall time); optionally slow
    or failing on log_step."""

    def __init__(self, *, delay_s: float = 0.0, fail_at: int | None = None, error: type[BaseException] = ValueError,
                 counts: Any = None) -> None:
        self.path = Path("fake.rrd")
        self.calls: list[tuple[str, Any, Any, float]] = []
        self.delay_s = delay_s
        self.fail_at = fail_at
        self.error = error
        self.counts = counts
        self.closed = False

    def _note(self, name: str, arg: Any) -> None:
        self.calls.append((name, arg, None if self.counts is None else dict(self.counts()), time.monotonic(),
                           threading.current_thread().name))

    def log_step(self, result: StepResult, *, arrival_ns: int | None = None) -> None:
        if self.fail_at is not None and len(self.calls) >= self.fail_at:
            raise self.error("boom")
        time.sleep(self.delay_s)
        self._note("step", arrival_ns)

    def log_truths(self, truths: Any) -> None:
        self._note("truth", truths[0][1])

    def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
        self._note("text", text)

    def maybe_flush(self) -> None:
        pass

    def close(self) -> None:
        self.closed = True


def _results(n: int) -> list[StepResult]:
    tr, dets, _ = maneuver_run(seed=3)
    return [tr.process([d]) for d in dets[:n]]


def test_a_recording_through_the_thread_is_the_one_written_on_the_loop(tmp_path: Path) -> None:
    kw: dict[str, Any] = {"duration_s": 20.0, "flush_rows": 300, "flush_interval_s": 1e9, "view_interval_s": 1e9}
    record_scenario("mix", tmp_path / "loop.rrd", **kw)
    record_scenario("mix", tmp_path / "thread.rrd", background=True, **kw)
    record_scenario("mix", tmp_path / "turns.rrd", background=True, behind=True, **kw)  # both threads make calls
    a, b, c = digest(tmp_path / "loop.rrd"), digest(tmp_path / "thread.rrd"), digest(tmp_path / "turns.rrd")
    assert a == b == c
    assert a["/record/estimates"]["rows"] > 500 and "/counts/applied" in a


def test_calls_are_made_in_order_and_none_is_lost_when_the_loop_waits_for_room() -> None:
    results = _results(40)
    fake = FakeSink(delay_s=0.005)
    w = SinkThread(max_rows=10)
    w.start(GuardedSink(fake))
    for k, r in enumerate(results):
        w.log_step(r, arrival_ns=k)
        w.log_truths([("t", k, None)])
    w.close()
    assert [(c[0], c[1]) for c in fake.calls] == [x for k in range(40) for x in (("step", k), ("truth", k))]
    assert w.waits > 0, "the queue never filled: the test did not reach the bound"
    assert fake.closed


def test_the_writer_waits_while_the_loop_is_busy_and_goes_on_after_twice_max_defer() -> None:
    fake = FakeSink()
    w = SinkThread(max_defer_s=1.5)
    w.start(GuardedSink(fake))
    w.loop_busy()
    t0 = time.monotonic()
    w.log_text(0, "while busy")
    time.sleep(0.3)
    assert fake.calls == [], "the writer ran while the loop was busy"
    w.loop_idle()
    deadline = time.monotonic() + 8.0
    while not fake.calls and time.monotonic() < deadline:
        time.sleep(0.005)
    assert fake.calls and fake.calls[0][3] - t0 < 1.2, "not made as soon as the loop went idle"
    w.loop_busy()  # busy for good and no behind() from the loop: the writer goes on by itself
    t1 = time.monotonic()
    w.log_text(0, "busy for good")
    deadline = time.monotonic() + 8.0
    while len(fake.calls) < 2 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert len(fake.calls) == 2 and 2.9 <= fake.calls[1][3] - t1 < 5.0
    assert fake.calls[1][4] == "fusion-recording"
    w.close()


def test_in_a_backlog_the_loop_makes_the_calls_itself() -> None:
    """A loop that stays behind makes the calls waiting on its own thread, in order, once the
    oldest has waited max_defer_s; meanwhile the writer's thread makes none of them. (The
    writer goes on by itself once a call has waited 2 max_defer_s: 0.5 s, so that a loaded
    machine's stalls of this test's loop, up to ~0.4 s, do not look like a loop that left them.)"""
    fake = FakeSink()
    w = SinkThread(max_defer_s=0.5)
    w.start(GuardedSink(fake))
    try:
        w.loop_busy()
        k = 0
        end = time.monotonic() + 3.0
        while time.monotonic() < end:  # batches of ~20 ms, each logging a text, with samples waiting after each
            w.log_text(0, str(k))
            k += 1
            time.sleep(0.02)
            w.maybe_flush()
            w.behind()
        assert 3 <= w.turns <= 6
        assert [c[1] for c in fake.calls] == [str(i) for i in range(len(fake.calls))]
        assert fake.calls and {c[4] for c in fake.calls} == {threading.current_thread().name}
        w.loop_idle()  # the loop waits for samples: the rest is the writer's
        w.log_text(0, str(k))
    finally:
        w.close()  # (a failed assertion above leaves no writer thread behind for the next tests)
    assert [c[1] for c in fake.calls] == [str(i) for i in range(k + 1)]
    assert fake.calls[-1][4] == "fusion-recording"


def test_a_bug_in_a_call_the_loop_makes_is_raised_at_once_and_stops_the_writer() -> None:
    w = SinkThread(max_defer_s=0.2)
    w.start(GuardedSink(FakeSink(fail_at=0)))
    w.loop_busy()
    w.log_step(_results(1)[0])
    w.behind()  # too early: nothing has waited max_defer_s
    assert w.turns == 0
    time.sleep(0.25)
    with pytest.raises(ValueError, match="boom"):
        w.behind()
    assert w.turns == 1
    with pytest.raises(ValueError, match="boom"):
        w.log_text(0, "after")
    with pytest.raises(ValueError, match="boom"):
        w.close()


def test_a_bug_in_the_recording_is_raised_on_the_loop_s_thread() -> None:
    results = _results(5)
    w = SinkThread()
    w.start(GuardedSink(FakeSink(fail_at=2)))
    with pytest.raises(ValueError, match="boom"):  # at a later call, or at close at the latest
        for r in results:
            w.log_step(r)
            time.sleep(0.05)
        w.close()
    with pytest.raises(ValueError, match="boom"):
        w.maybe_flush()


def test_a_failing_file_stops_the_recording_only() -> None:
    results = _results(5)
    fake = FakeSink(fail_at=2, error=OSError)
    w = SinkThread()
    w.start(GuardedSink(fake))
    for r in results:
        w.log_step(r)
    w.close()  # no exception: the guard took it
    assert w.error is not None and "OSError: boom" in w.error
    assert len(fake.calls) == 2 and not fake.closed  # every call after the failure is a no-op


def test_the_counts_the_sink_sees_are_those_taken_before_its_call() -> None:
    n = [0]
    w = SinkThread(counts=lambda: {"applied": n[0]}, counts_every_s=0.0)
    fake = FakeSink(delay_s=0.002, counts=w.counts)
    w.start(GuardedSink(fake))
    for k in range(30):
        n[0] = k
        w.log_text(0, str(k))
    n[0] = 99
    w.close()
    assert [c[2]["applied"] for c in fake.calls] == list(range(30))


def test_counts_are_taken_at_most_every_counts_every_s_and_at_close() -> None:
    taken = []

    def source() -> dict[str, int]:
        taken.append(time.monotonic())
        return {"applied": len(taken)}

    w = SinkThread(counts=source, counts_every_s=10.0)
    w.start(GuardedSink(FakeSink()))
    for k in range(50):
        w.log_text(0, str(k))
        w.maybe_flush()
    assert len(taken) == 1
    w.close()
    assert len(taken) == 2
    assert w.counts() == {"applied": 2}


def test_idle_is_true_once_every_call_is_made() -> None:
    gate = threading.Event()

    class Blocking(FakeSink):
        def log_text(self, t_ns: int, text: str, level: str = "INFO") -> None:
            gate.wait(5.0)
            super().log_text(t_ns, text, level)

    w = SinkThread()
    w.start(GuardedSink(Blocking()))
    w.log_text(0, "x")
    time.sleep(0.05)
    assert not w.idle()
    gate.set()
    deadline = time.monotonic() + 5.0
    while not w.idle() and time.monotonic() < deadline:
        time.sleep(0.005)
    assert w.idle()
    w.close()


def test_the_writer_stops_at_a_pause_inside_a_call_while_the_loop_is_busy() -> None:
    """A flush is one call of many parts; the sink calls pause() between them and the writer
    waits there for the loop (within max_defer_s), not only between calls."""
    in_call, go = threading.Event(), threading.Event()

    class Parted(FakeSink):
        pause: Any = None

        def maybe_flush(self) -> None:
            self._note("part 1", None)
            in_call.set()
            go.wait(5.0)
            self.pause()
            self._note("part 2", None)

    fake = Parted()
    w = SinkThread(max_defer_s=1.5)
    fake.pause = w.pause
    w.start(GuardedSink(fake))
    w.maybe_flush()
    assert in_call.wait(5.0)
    w.loop_busy()  # a scan arrives while the writer is inside the call
    go.set()
    time.sleep(0.3)
    assert [c[0] for c in fake.calls] == ["part 1"], "the writer went on with the call while the loop was busy"
    t_idle = time.monotonic()
    w.loop_idle()
    deadline = time.monotonic() + 8.0
    while len(fake.calls) < 2 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert [c[0] for c in fake.calls] == ["part 1", "part 2"] and fake.calls[1][3] - t_idle < 1.0
    # busy for good: the call goes on once the round's budget is spent
    in_call.clear()
    go.clear()
    w.maybe_flush()
    assert in_call.wait(5.0)
    w.loop_busy()
    t_busy = time.monotonic()
    go.set()
    while len(fake.calls) < 4 and time.monotonic() < deadline:
        time.sleep(0.005)
    assert len(fake.calls) == 4 and fake.calls[3][3] - t_busy < 4.0
    w.close()


def test_a_pause_on_any_other_thread_than_the_writer_s_returns_at_once() -> None:
    w = SinkThread(max_defer_s=5.0)
    w.start(GuardedSink(FakeSink()))
    w.loop_busy()
    t0 = time.monotonic()
    w.pause()  # the loop's thread (a sink used without the writer's thread never waits)
    assert time.monotonic() - t0 < 0.5
    w.loop_idle()
    w.close()
