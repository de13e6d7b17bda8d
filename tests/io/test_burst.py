"""fusion.io.burst.drain_burst on the real intake queue, fed by a producer thread as Zenoh's
callbacks feed it: a burst with short pauses comes out as one batch, a pause longer than the gap
ends the batch, the wait is capped by the linger and by the batch limit (the batch then says it
was cut while its burst was still arriving), and with no linger it is the plain drain."""

from __future__ import annotations

import threading
import time

from fusion.io.burst import Drained, drain_burst
from fusion.io.intake_queue import IntakeLimits, IntakeQueue

KEY = "fusion/demo/meas/radar1"


def queue() -> IntakeQueue:
    return IntakeQueue(IntakeLimits(queue_max=100_000, queue_max_bytes=10**9, max_message_bytes=1000),
                       known=["radar1"])


def offer(q: IntakeQueue, wake: threading.Event, i: int) -> None:
    assert q.offer(time.time_ns(), KEY, 8, lambda: i.to_bytes(8, "little")) is None
    wake.set()


def producer(q: IntakeQueue, wake: threading.Event, parts: list[int], pause_s: float) -> threading.Thread:
    """Offers parts[0] samples, pauses pause_s, parts[1] samples, ... (a burst with pauses)."""
    def run() -> None:
        i = 0
        for k, n in enumerate(parts):
            if k:
                time.sleep(pause_s)
            for _ in range(n):
                offer(q, wake, i)
                i += 1
    t = threading.Thread(target=run)
    return t


def first_batch(q: IntakeQueue, wake: threading.Event, **kw: object) -> Drained:
    """What drain_burst returns once the first sample is there."""
    assert wake.wait(5.0)
    return drain_burst(q, wake, kw.pop("limit", 10_000), **kw)  # type: ignore[arg-type]


def test_a_burst_with_pauses_shorter_than_the_gap_is_one_batch() -> None:
    q, wake = queue(), threading.Event()
    t = producer(q, wake, [1, 300, 300], pause_s=0.02)
    t.start()
    batch, cut = first_batch(q, wake, gap_s=0.2, linger_s=5.0)
    t.join()
    assert len(batch) == 601 and not cut  # ended by the quiet after it
    assert [int.from_bytes(r[2], "little") for r in batch] == list(range(601))  # in arrival order
    assert len(q) == 0


def test_on_chunk_sees_each_part_as_it_is_drained() -> None:
    """on_chunk is called with the batch's parts in order (the first drain, then what each look
    after a pause found), before the wait for the rest: their concatenation is the batch."""
    q, wake = queue(), threading.Event()
    t = producer(q, wake, [1, 300, 300], pause_s=0.05)
    t.start()
    parts: list[list[int]] = []
    batch, cut = first_batch(q, wake, gap_s=0.2, linger_s=5.0,
                             on_chunk=lambda chunk: parts.append([int.from_bytes(r[2], "little") for r in chunk]))
    t.join()
    assert len(batch) == 601 and not cut
    assert len(parts) >= 3 and [i for p in parts for i in p] == list(range(601))  # a part per pause at least


def test_the_gap_is_counted_from_the_look_that_found_samples() -> None:
    """Work done in on_chunk overlaps the wait for the burst's end: a part whose work outlasts
    the gap ends the batch as soon as the work is done and nothing more came (not a whole gap
    later); samples that came during the work are found and stay in the batch."""
    q, wake = queue(), threading.Event()
    t = producer(q, wake, [1, 300], pause_s=0.05)
    t.start()
    calls: list[int] = []

    def work(chunk: list) -> None:
        calls.append(len(chunk))
        time.sleep(0.6)

    assert wake.wait(5.0)
    t0 = time.monotonic()
    batch, cut = drain_burst(q, wake, 10_000, gap_s=0.5, linger_s=30.0, on_chunk=work)
    took = time.monotonic() - t0
    t.join()
    assert len(batch) == 301 and not cut and calls[0] == 1 and sum(calls) == 301
    assert took < 0.6 * len(calls) + 0.35, (took, calls)  # a gap counted after the work: >= 0.6 n + 0.5


def test_a_pause_longer_than_the_gap_ends_the_batch() -> None:
    q, wake = queue(), threading.Event()
    t = producer(q, wake, [200, 200], pause_s=0.5)
    t.start()
    batch, cut = first_batch(q, wake, gap_s=0.05, linger_s=5.0)
    t.join()
    assert len(batch) == 200 and len(q) == 200 and not cut


def test_no_linger_is_the_plain_drain() -> None:
    q, wake = queue(), threading.Event()
    t = producer(q, wake, [1, 300], pause_s=0.3)
    t.start()
    batch, cut = first_batch(q, wake, gap_s=1.0, linger_s=0.0)
    t.join()
    assert len(batch) == 1 and len(q) == 300 and not cut  # short of the limit: as before, not cut


def test_the_wait_is_capped_by_the_linger_and_by_the_limit() -> None:
    q, wake = queue(), threading.Event()
    stop = threading.Event()

    def steady() -> None:  # a sample every 2 ms, never quiet for the 50 ms gap
        i = 0
        while not stop.is_set():
            offer(q, wake, i)
            i += 1
            time.sleep(0.002)

    t = threading.Thread(target=steady)
    t.start()
    try:
        assert wake.wait(5.0)
        t0 = time.monotonic()
        batch, cut = drain_burst(q, wake, 100_000, gap_s=0.05, linger_s=0.3)
        took = time.monotonic() - t0
        assert 0.3 <= took < 2.0 and len(batch) > 1 and cut  # the linger ran out, samples still coming
        while len(q) < 5:
            time.sleep(0.005)
        t0 = time.monotonic()
        batch, cut = drain_burst(q, wake, 5, gap_s=0.05, linger_s=30.0)
        assert len(batch) == 5 and time.monotonic() - t0 < 5.0 and cut  # the limit reached
    finally:
        stop.set()
        t.join()


def test_samples_queued_as_the_gap_s_wait_times_out_stay_in_the_batch() -> None:
    """The wait's timeout is seen only once the loop's thread holds the GIL again; a Zenoh
    callback that held it first may have queued the burst's next samples meanwhile: they are
    part of the burst, not the start of the next batch."""
    q = queue()

    class LateWake(threading.Event):
        """Times out, and the producer queues two samples just as it does."""

        calls = 0

        def wait(self, timeout: float | None = None) -> bool:
            self.calls += 1
            if self.calls == 1:
                time.sleep(timeout or 0.0)
                for i in (100, 101):
                    assert q.offer(time.time_ns(), KEY, 8, lambda i=i: i.to_bytes(8, "little")) is None
                return False
            return super().wait(timeout)

    wake = LateWake()
    offer(q, wake, 0)
    batch, cut = drain_burst(q, wake, 10_000, gap_s=0.01, linger_s=1.0)
    assert [int.from_bytes(r[2], "little") for r in batch] == [0, 100, 101] and not cut
