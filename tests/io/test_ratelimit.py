"""Rate-limited warnings: a flood cannot fill the disk; what was suppressed is reported."""

from __future__ import annotations

import logging

import pytest

from fusion.io.ratelimit import RateLimitedLog


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
    assert msgs == ["bad 0", "bad 1", "bad 2", "late", "7 more nan warnings suppressed in the last minute", "bad again"]
