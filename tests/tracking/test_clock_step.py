"""Clocks.step (the intake's one call per detection) is exactly reference, observe and
watermark in the order the intake used them, in every state the clocks go through."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.tracking.clock import Clocks

FUTURE_NS = 10_000_000_000


def _composed(c: Clocks, source: str, t: int, a: int | None, future_ns: int) -> tuple[int | None, int | None]:
    """What Intake._window did before Clocks.step."""
    if a is None:
        c.observe(source, t, None)
        ref = c.reference(source, None)
    else:
        ref = c.reference(source, a)
        if ref is None or t <= ref + future_ns:
            c.observe(source, t, a)
    return ref, c.watermark(a)


def _state(c: Clocks) -> tuple[object, ...]:
    return (c.first_arrival_ns, tuple((s, k.state(), k.offset, k.settled) for s, k in c.sources.items()))


@pytest.mark.parametrize("seed", range(6))
def test_step_is_reference_observe_watermark(seed: int) -> None:
    rng = np.random.default_rng(seed)
    kw = dict(samples=int(rng.integers(1, 9)), outliers=int(rng.integers(0, 3)), idle_ns=2_000_000_000)
    a, b = Clocks(["r", "c", "u"], **kw), Clocks(["r", "c", "u"], **kw)
    arrival = 10**12
    no_arrival = seed % 3 == 0  # some runs without arrival times, the others with a few missing
    for i in range(3000):
        arrival += int(rng.integers(0, 300_000_000))
        src = str(rng.choice(["r", "c", "u"], p=[0.6, 0.35, 0.05]))
        t = arrival + int(rng.normal(0, 1e9))
        if rng.random() < 0.02:
            t += int(rng.choice([-1, 1])) * 30_000_000_000  # a wrong timestamp, far off
        arr = None if no_arrival or rng.random() < 0.01 else arrival
        if i == 1500:  # a checkpoint restored without its first arrival
            for s, k in a.sources.items():
                b.sources[s].restore(*k.state())
            a.restore_first_arrival(None)
            b.restore_first_arrival(None)
        assert a.step(src, t, arr, FUTURE_NS) == _composed(b, src, t, arr, FUTURE_NS), i
        assert _state(a) == _state(b), i
