"""The intake queue's byte count is the memory its samples take (payload, key and the Python
objects around them), so queue_max_bytes bounds what a backlog costs."""

from __future__ import annotations

import time
import tracemalloc

from bench.e2e_load import Scene
from fusion.io.intake_queue import IntakeLimits, IntakeQueue


def test_counted_bytes_are_the_traced_bytes() -> None:
    ticks = Scene(200, seed=3).ticks(time.time_ns())
    payloads = [p for _ in range(20) for p in next(ticks)[2]]  # radar and camera messages
    limits = IntakeLimits(queue_max=10**6, queue_max_bytes=10**9, max_message_bytes=65_536, rate_hz=0.0, burst=1000)
    q = IntakeQueue(limits, known=["radar1", "cam1"])
    sensors = ["radar1", "cam1"]
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        for i, p in enumerate(payloads):
            key = "/".join(("fusion", "demo", "meas", sensors[i % 2]))  # a str per sample, as zenoh's key_expr
            assert q.offer(time.time_ns(), key, len(p), lambda p=p: bytes(bytearray(p))) is None
        traced = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert len(q) == len(payloads) >= 2000
    assert 0.9 <= q.nbytes / traced <= 1.1, \
        f"counted {q.nbytes / len(q):.0f} bytes per sample, traced {traced / len(q):.0f}"
