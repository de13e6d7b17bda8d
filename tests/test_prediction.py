"""fusion.prediction: the cadence of periodic snapshots and the snapshot query's parameters."""

from __future__ import annotations

import pytest

from fusion.errors import InputError
from fusion.prediction import MAX_CATCH_UP, Cadence, snapshot_time


def test_ticks_are_multiples_of_the_period_from_the_first_measurement() -> None:
    c = Cadence(500)
    assert c.due(None) == [] and c.due(900) == [], "no tick before the first measurement is known"
    assert c.due(400, first_ns=100) == []
    assert c.due(500) == [500]
    assert c.due(999) == []
    assert c.due(2000) == [1000, 1500, 2000]
    assert c.due(1900) == [], "the clock going back publishes nothing again"
    assert c.due(2499) == [] and c.due(2500) == [2500]


def test_a_burst_gets_every_tick_from_its_start() -> None:
    c = Cadence(1000)
    assert c.due(3500, first_ns=0) == [0, 1000, 2000, 3000]


def test_a_clock_jump_publishes_the_newest_ticks_only() -> None:
    c = Cadence(10)
    ticks = c.due(10 * (MAX_CATCH_UP + 49), first_ns=10)
    assert len(ticks) == MAX_CATCH_UP and ticks[-1] == 10 * (MAX_CATCH_UP + 49) and c.skipped == 49


def test_the_period_must_be_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        Cadence(0)


@pytest.mark.parametrize(("params", "want"), [([], None), ([("t_ns", "20000000000")], 20_000_000_000),
                                              ([("t_ns", "-5")], -5)], ids=["none", "t", "negative"])
def test_snapshot_time(params, want) -> None:
    assert snapshot_time(params) == want


@pytest.mark.parametrize(("params", "match"), [([("t_ns", "1.5")], "integer"), ([("t", "1")], "unknown")],
                         ids=["float", "unknown"])
def test_snapshot_time_refused(params, match) -> None:
    with pytest.raises(InputError, match=match):
        snapshot_time(params)
