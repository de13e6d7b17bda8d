"""Where everything is at a given time: predicted snapshots, on request and on a cadence.

Both answer with a Snapshot message (fusion.messages) of every confirmed track predicted to a
sensor time T with its covariance (`Tracker.predict`: x(T) = f(x, T - t), P(T) = F P F' + Q;
status "predicted"; a track updated after T is given at its last update, status "confirmed").

On request: the `snapshot` queryable with the parameter `t_ns=T` (integer nanoseconds of sensor
time), e.g. `fusion/<ns>/snapshot?t_ns=20000000000`. Without parameters the queryable answers
the latest published estimates (fusion.publication). Any other parameter, or a t_ns that is not
an integer, is answered with an error naming it.

On a cadence (`[publication] period_s`): the tracker has no clock of its own, so the cadence runs
on the stream's clock, `Tracker.now_ns` (the most advanced source clock, in sensor time). The
ticks are the multiples of the period, T_k = k * period_ns. After each batch the service has
processed, every tick T with last published tick < T <= now_ns is due, and the snapshot
predicted to T (from the tracks as they are after that batch) is published on
`fusion/<ns>/predicted`, in increasing T. The first tick is the first multiple at or after the
earliest sensor time of the first batch that brought measurements (so a stream that arrives in
one burst still gets every tick from its start). When more than `MAX_CATCH_UP` ticks are due
at once (a jump of the clock), only the newest MAX_CATCH_UP are published and the others are
counted as skipped. The ticks depend only on the sensor times of the stream; the predictions
also on how the records were batched (what the tracker held when a tick fell due): a replay
that feeds the same records in the same batches publishes the same ticks and predictions.
Since the stream clock trails the newest measurement, a track updated at or after a tick by the
batch that made it due is given at that update (status "confirmed"); the tracks not updated
since (other sensors, coasting) are the ones carried forward.
"""

from __future__ import annotations

from collections.abc import Iterable

from fusion import messages as m
from fusion.errors import InputError
from fusion.io import wire
from fusion.tracking.tracker import Tracker

MAX_CATCH_UP = 100  # ticks published after one batch at most


def predicted_key(ns: str) -> str:
    """Where the periodic predicted snapshots go."""
    return f"fusion/{m.check_id('namespace', ns)}/predicted"


def snapshot_time(parameters: Iterable[tuple[str, str]]) -> int | None:
    """The t_ns a snapshot query asks for (None: no parameters, the latest estimates).
    InputError names an unknown parameter or a t_ns that is not an integer."""
    t_ns = None
    for name, value in parameters:
        if name != "t_ns":
            raise InputError(f"unknown snapshot parameter {name!r}; known: t_ns (sensor time, integer ns)")
        try:
            t_ns = int(value, 10)
        except ValueError:
            raise InputError(f"snapshot parameter t_ns must be an integer of nanoseconds, got {value!r}") from None
    return t_ns


def encode_predicted(tracker: Tracker, t_ns: int) -> bytes:
    """A Snapshot message of every confirmed track predicted to t_ns."""
    layout, model = tracker.layout, tracker.model_name
    return wire.encode_snapshot([wire.estimate_message(e, layout=layout, model=model) for e in tracker.predict(t_ns)])


class Cadence:
    """The ticks of a periodic publication on the stream's clock (see the module docstring)."""

    def __init__(self, period_ns: int) -> None:
        if period_ns <= 0:
            raise ValueError(f"the period must be positive, got {period_ns} ns")
        self.period_ns = period_ns
        self.next_ns: int | None = None  # the next tick to publish
        self.skipped = 0

    def due(self, now_ns: int | None, first_ns: int | None = None) -> list[int]:
        """The ticks due at stream time now_ns, in increasing order (at most MAX_CATCH_UP);
        first_ns: the earliest sensor time of the batch (starts the cadence)."""
        p = self.period_ns
        if self.next_ns is None and first_ns is not None:
            self.next_ns = -(-first_ns // p) * p  # the first multiple at or after first_ns
        if now_ns is None or self.next_ns is None:
            return []
        if now_ns < self.next_ns:
            return []
        last = now_ns // p * p
        n = (last - self.next_ns) // p + 1
        first = self.next_ns if n <= MAX_CATCH_UP else last - (MAX_CATCH_UP - 1) * p
        self.skipped += max(0, n - MAX_CATCH_UP)
        self.next_ns = last + p
        return list(range(first, last + 1, p))
