"""The intake queue alone: byte limit, bounds in samples and bytes, rate limits, fairness."""

from __future__ import annotations

import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.io.intake_queue import RECORD_OVERHEAD_BYTES, IntakeLimits, IntakeQueue, source_class

KNOWN = ("cam1", "radar1")


def key(kind: str, ident: str) -> str:
    return f"fusion/demo/{kind}/{ident}"


def offer(q: IntakeQueue, t: int, k: str, payload: bytes = b"x" * 10) -> str | None:
    return q.offer(t, k, len(payload), lambda: payload)


def adds_up(q: IntakeQueue) -> bool:
    return q.offered == q.handed_out + q.refused_total + len(q)


@pytest.mark.parametrize(("k", "cls"), [
    (key("meas", "cam1"), "meas/cam1"), (key("meas", "ghost"), "other"), (key("truth", "x"), "truth"),
    (key("truth", "y"), "truth"), ("fusion/demo/meas/*", "other"), ("fusion/demo/**", "other"),
    (key("input", "cam1"), "input/cam1"), ("fusion/demo/meas/cam1/x", "other"),
], ids=str)
def test_source_classes_are_bounded_in_number(k: str, cls: str) -> None:
    assert source_class(k, frozenset(KNOWN)) == cls


def test_refusals_are_counted_by_the_kind_their_key_names() -> None:
    """Whatever the class: an input of an unconfigured source shares "other" with unknown sensors,
    yet is counted as an input; a sample evicted to make room is counted by its own key."""
    q = IntakeQueue(IntakeLimits(queue_max=1, queue_max_bytes=10**6, max_message_bytes=100), known=KNOWN)
    big = b"z" * 101
    for k in (key("input", "wheel"), key("truth", "x"), key("meas", "ghost"), "fusion/demo/**"):
        assert offer(q, 1, k, big) == "too_large"
    assert offer(q, 2, key("truth", "x")) is None
    assert offer(q, 3, key("meas", "cam1")) is None  # the queue is full: truth, the bigger class, makes room
    assert q.refused == {"too_large": 4, "overload": 1} and adds_up(q)
    assert q.refused_kinds == {"input": 1, "truth": 2, "meas": 1, "other": 1}


def test_a_payload_over_the_byte_limit_is_refused_without_being_copied() -> None:
    q = IntakeQueue(IntakeLimits(queue_max=10, queue_max_bytes=10**6, max_message_bytes=100), known=KNOWN)

    def never() -> bytes:
        raise AssertionError("the payload of a refused sample was copied")

    assert q.offer(1, key("meas", "cam1"), 101, never) == "too_large"
    assert offer(q, 2, key("meas", "cam1"), b"y" * 100) is None
    assert q.refused == {"too_large": 1} and len(q) == 1 and adds_up(q)


@pytest.mark.parametrize("kind", ["truth", "meas", "other"], ids=str)
def test_every_key_is_bounded_in_samples(kind: str) -> None:
    q = IntakeQueue(IntakeLimits(queue_max=50, queue_max_bytes=10**9, max_message_bytes=1000), known=KNOWN)
    k = {"truth": key("truth", "x"), "meas": key("meas", "cam1"), "other": "fusion/demo/meas/*"}[kind]
    for i in range(1000):
        offer(q, i, k)
    assert len(q) == 50 and q.max_depth == 50
    assert q.refused == {"overload": 950} and adds_up(q)
    assert [r[0] for r in q.drain(1000)] == list(range(50)), "the oldest are kept, the newcomers refused"


def test_the_queue_is_bounded_in_bytes() -> None:
    cost = 1000 + len(key("truth", "x")) + RECORD_OVERHEAD_BYTES
    q = IntakeQueue(IntakeLimits(queue_max=10**6, queue_max_bytes=10 * cost, max_message_bytes=5000), known=KNOWN)
    for i in range(100):
        offer(q, i, key("truth", "x"), b"z" * 1000)
    assert len(q) == 10 and q.nbytes == 10 * cost and q.max_bytes <= 10 * cost
    assert q.refused == {"overload": 90} and adds_up(q)


def test_a_flood_costs_only_the_flooding_source() -> None:
    """radar1 fills the queue; cam1's samples then evict radar1's oldest, never the reverse."""
    q = IntakeQueue(IntakeLimits(queue_max=100, queue_max_bytes=10**9, max_message_bytes=1000), known=KNOWN)
    for i in range(5000):
        offer(q, i, key("meas", "radar1"))
    for i in range(20):
        assert offer(q, 10_000 + i, key("meas", "cam1")) is None
    assert len(q) == 100 and q.depth_by_source() == {"meas/cam1": 20, "meas/radar1": 80}
    assert q.refused_by_source == {"meas/radar1:overload": 4920}
    assert adds_up(q)


def test_drain_hands_out_the_oldest_across_sources_in_arrival_order() -> None:
    """Interleaved sources come out in the order they were queued, whatever the batch size:
    no batch holds a sample newer than one left behind for the next batch."""
    q = IntakeQueue(IntakeLimits(queue_max=10**4, queue_max_bytes=10**9, max_message_bytes=1000), known=KNOWN)
    for i in range(300):  # radar1 twice as often as cam1, as the shipped sensors (10 Hz, 5 Hz)
        offer(q, i, key("meas", "cam1" if i % 3 == 2 else "radar1"))
    got: list[int] = []
    for limit in (7, 1, 50, 13, 1000):
        batch = [r[0] for r in q.drain(limit)]
        assert batch == sorted(batch) and len(batch) == min(limit, 300 - len(got))
        assert not got or batch[0] > got[-1], "a sample older than the last batch's newest was held back"
        got.extend(batch)
    assert got == list(range(300)) and len(q) == 0 and adds_up(q)


def test_a_flood_delays_another_source_by_at_most_the_queue_bound() -> None:
    """Fairness is enforced at offer time: radar1's flood is cut to its share of the queue, so
    cam1's samples, offered after it, are handed out within the next queue_max samples."""
    q = IntakeQueue(IntakeLimits(queue_max=100, queue_max_bytes=10**9, max_message_bytes=1000), known=KNOWN)
    for i in range(1000):
        offer(q, i, key("meas", "radar1"))
    for i in range(5):
        assert offer(q, 2000 + i, key("meas", "cam1")) is None
    batch = q.drain(100)
    assert sum(1 for r in batch if r[1].endswith("cam1")) == 5, "cam1 waited behind radar1's flood"
    assert [r[0] for r in batch] == sorted(r[0] for r in batch)
    assert len(q) == 0 and adds_up(q)


def test_the_rate_limit_is_per_source() -> None:
    now = [0.0]
    q = IntakeQueue(IntakeLimits(queue_max=10**6, queue_max_bytes=10**9, max_message_bytes=1000, rate_hz=100.0,
                                 burst=10), known=KNOWN, clock=lambda: now[0])
    got = [offer(q, i, key("meas", "radar1")) for i in range(50)]
    assert got.count(None) == 10 and got.count("rate_limited") == 40
    assert offer(q, 99, key("meas", "cam1")) is None, "cam1 is not limited by radar1's rate"
    now[0] = 0.05  # 5 tokens back
    got = [offer(q, 100 + i, key("meas", "radar1")) for i in range(10)]
    assert got.count(None) == 5
    assert adds_up(q)


def test_offer_and_drain_from_many_threads_add_up() -> None:
    q = IntakeQueue(IntakeLimits(queue_max=500, queue_max_bytes=10**9, max_message_bytes=1000), known=KNOWN)
    got: list[int] = []
    stop = threading.Event()

    def drainer() -> None:
        while not stop.is_set() or len(q):
            got.extend(r[0] for r in q.drain(64))

    def producer(k: str, base: int) -> None:
        for i in range(5000):
            offer(q, base + i, k)

    d = threading.Thread(target=drainer)
    d.start()
    ps = [threading.Thread(target=producer, args=(key("meas", s), 10**6 * j)) for j, s in enumerate(KNOWN + ("x",))]
    for p in ps:
        p.start()
    for p in ps:
        p.join()
    stop.set()
    d.join()
    assert q.offered == 15_000 and len(got) + q.refused_total == 15_000 and len(set(got)) == len(got)


def test_limits_are_checked() -> None:
    with pytest.raises(ValueError):
        IntakeLimits(queue_max=0, queue_max_bytes=1, max_message_bytes=1)
    with pytest.raises(ValueError):
        IntakeLimits(queue_max=1, queue_max_bytes=1, max_message_bytes=1, rate_hz=-1.0)


def _state(q: IntakeQueue) -> tuple:
    return (q.offered, len(q), q.nbytes, q.max_depth, q.max_bytes, dict(q.refused), dict(q.refused_by_source),
            q.depth_by_source(), q.drain(10**6))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([key("meas", "cam1"), key("meas", "radar1"), key("truth", "a"),
                                           key("meas", "ghost")]), st.integers(0, 140)), max_size=120),
       st.lists(st.integers(1, 40), min_size=1, max_size=10), st.sampled_from([0.0, 50.0]))
def test_offer_many_is_offer_sample_by_sample(samples: list[tuple[str, int]], cuts: list[int], rate: float) -> None:
    """A chunk offered at once (the service's intake) leaves the queue, its counts and its
    refusals as the same samples offered one at a time, however the stream is cut into chunks:
    key changes inside a chunk, payloads over the byte limit, evictions and rate limits."""
    t = [0.0]
    lim = IntakeLimits(queue_max=25, queue_max_bytes=12_000, max_message_bytes=120, rate_hz=rate, burst=5)
    one = IntakeQueue(lim, known=KNOWN, clock=lambda: t[0])
    many = IntakeQueue(lim, known=KNOWN, clock=lambda: t[0])
    offers = [(i, k, n, (lambda n=n: b"p" * n)) for i, (k, n) in enumerate(samples)]
    expected = [(i, r) for i, (a, k, n, p) in enumerate(offers) if (r := one.offer(a, k, n, p)) is not None]
    got: list[tuple[int, str]] = []
    start, c = 0, 0
    while start < len(offers):
        chunk = offers[start:start + cuts[c % len(cuts)]]
        found: list[tuple[int, str]] = []
        queued = many.offer_many(chunk, found)
        assert queued == len(chunk) - len(found)
        got.extend((start + i, r) for i, r in found)
        start, c = start + len(chunk), c + 1
    assert got == expected
    assert _state(many) == _state(one)
    assert adds_up(many)
