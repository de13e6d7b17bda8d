"""Samples taken from Zenoh channels by a thread per channel, many per hold of the GIL.

A callback subscriber runs Python on Zenoh's thread for every sample, and every call takes the
GIL from the service's loop and gives it back. Here each subscriber hands its samples to a
Zenoh FIFO channel instead, and one thread per channel waits in the channel's `recv` (without
the GIL), then takes what the channel holds (up to `chunk` samples), each stamped with the time
it was taken, and passes them to `take` in one call: one hand-over of the GIL per chunk, not
per sample. Measured (`python -m bench --only handover`: a loop doing ~14 us of Python per
sample, a publisher process blasting 120 000 samples on loopback, 3 interleaved pairs): 55k
samples/s fed by a callback, 69k/s by this (1.08-1.31x per pair); the service's blast at 1000
targets went from 29.0k to 34.5k measurements/s (bench/HISTORY.md). A first probe of a loop that
took the samples itself was ~7 % faster still, but a busy loop would then leave its samples in
Zenoh, outside the intake queue's bounds and counts: not done.

A full channel makes Zenoh wait, as a slow callback did. An exception from `take` (a bug) is
logged and kept in `errors` (the last 100), and the thread goes on, as Zenoh does with a callback's. When its
subscriber is undeclared a channel closes: its thread takes what is left in it, then ends
(`join`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

log = logging.getLogger("fusion.intake")

Taken = list[tuple[int, Any]]  # (arrival_ns: when taken from the channel, sample), in the channel's order


class ChannelIntake:
    """A thread per Zenoh channel (`handlers`: the receiving ends of the subscribers' FIFO
    channels) passing its samples to `take` in chunks (module docstring)."""

    def __init__(self, handlers: Sequence[Any], take: Callable[[Taken], None], *, chunk: int = 1000,
                 name: str = "fusion-intake") -> None:
        self._take = take
        self._chunk = chunk
        self.errors: deque[Exception] = deque(maxlen=100)  # the last of what `take` raised (a bug; logged)
        self._threads = [threading.Thread(target=self._run, args=(h,), name=f"{name}-{i}", daemon=True)
                         for i, h in enumerate(handlers)]
        for t in self._threads:
            t.start()

    def _run(self, handler: Any) -> None:
        recv, try_recv, now, chunk, take = handler.recv, handler.try_recv, time.time_ns, self._chunk, self._take
        while True:
            try:
                first = recv()  # blocks without the GIL
            except Exception:  # zenoh.ZError: closed and empty (its subscriber undeclared)
                return
            taken = [(now(), first)]
            closed = False
            while len(taken) < chunk:
                try:
                    s = try_recv()
                except Exception:  # closed and empty
                    closed = True
                    break
                if s is None:
                    break
                taken.append((now(), s))
            try:
                take(taken)
            except Exception as e:  # a bug in `take`: said and kept, the channel still drained
                self.errors.append(e)
                log.exception("intake: %d samples from a Zenoh channel lost", len(taken))
            if closed:
                return

    def join(self, timeout_s: float = 5.0) -> bool:
        """Wait for the threads to end (their subscribers undeclared); True if they all did."""
        deadline = time.monotonic() + timeout_s
        for t in self._threads:
            t.join(max(deadline - time.monotonic(), 0.0))
        return not any(t.is_alive() for t in self._threads)
