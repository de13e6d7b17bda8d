"""Rate-limited warnings: a flood cannot fill the disk or the terminal; what was held back is
reported as counts."""

from __future__ import annotations

import logging

import pytest

from fusion.io.ratelimit import RateLimitedLog, flush_all


def test_limit_per_reason_and_summary(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    log = RateLimitedLog(logging.getLogger("t"), per_minute=3, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING):
        shown = [log.warn("nan", "bad %d", i) for i in range(10)]
        other = log.warn("future", "late")
        now[0] = 61.0
        again = log.warn("nan", "bad again")
    assert shown == [True] * 3 + [False] * 7
    assert other and again
    msgs = [r.getMessage() for r in caplog.records]
    assert msgs == ["bad 0", "bad 1", "bad 2", "late", "... and 7 more 'nan' warnings not shown", "bad again"]
    assert log.totals == {"nan": 11, "future": 1} and log.suppressed == {"nan": 7}


def test_burst_then_steady_rate(caplog: pytest.LogCaptureFixture) -> None:
    """A burst of 100 at once shows `burst` lines; afterwards one line per 60/per_minute s."""
    now = [0.0]
    log = RateLimitedLog(logging.getLogger("t"), per_minute=60, burst=5, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING):
        shown = sum(log.warn("duplicate", "dup %d", i) for i in range(100))
        assert shown == 5
        steady = 0
        for _ in range(30):  # 30 s at 10 warnings a second: about one line a second gets through
            for _ in range(10):
                now[0] += 0.1
                steady += log.warn("duplicate", "dup")
        assert 29 <= steady <= 31
    lines = [r.getMessage() for r in caplog.records]
    assert not any("more" in x for x in lines), "held-back counts are reported at most once a minute"
    assert log.totals["duplicate"] == 400 and log.suppressed["duplicate"] == 400 - 5 - steady


def test_flush_all_reports_what_is_pending(caplog: pytest.LogCaptureFixture) -> None:
    log = RateLimitedLog(logging.getLogger("t"), per_minute=60, burst=2, clock=lambda: 0.0)
    with caplog.at_level(logging.WARNING):
        for i in range(12):
            log.warn("duplicate", "dup %d", i)
        caplog.clear()
        flush_all()
        flush_all()  # nothing pending any more: no second summary
    assert [r.getMessage() for r in caplog.records] == ["... and 10 more 'duplicate' warnings not shown (12 in all)"]


def test_refuses_nonsense_limits() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        RateLimitedLog(logging.getLogger("t"), per_minute=0)
