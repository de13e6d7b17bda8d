"""Rate-limited warnings: a flood of bad input can neither fill the disk nor the terminal.

Per reason, a token bucket: up to `burst` lines at once, then on average at most `per_minute`
per minute (a token comes back every 60/per_minute seconds, at most `burst` are kept). What is
held back is counted: the next line of that reason is preceded by "... and N more" for it, and
`flush()` (or `flush_all()`, which a command calls before it exits) logs what is still pending,
so every warning is accounted for as a count even when its line was not shown.
"""

from __future__ import annotations

import logging
import time
import weakref
from collections import Counter
from collections.abc import Callable

_live: weakref.WeakSet[RateLimitedLog] = weakref.WeakSet()


class RateLimitedLog:
    """Warnings per reason, rate-limited (see the module docstring). `totals` counts every
    warning asked for, `suppressed` those whose line was held back."""

    def __init__(self, logger: logging.Logger, *, per_minute: int = 60, burst: int = 5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if per_minute < 1 or burst < 1:
            raise ValueError("per_minute and burst must be at least 1")
        self.logger = logger
        self.per_minute = per_minute
        self.burst = min(burst, per_minute)
        self._clock = clock
        self._bucket: dict[str, tuple[float, float]] = {}  # reason -> (tokens, time of last refill)
        self._pending: Counter[str] = Counter()  # held back and not yet reported
        self._reported: dict[str, float] = {}  # reason -> when its pending count was last reported
        self.totals: Counter[str] = Counter()
        self.suppressed: Counter[str] = Counter()
        _live.add(self)

    def warn(self, reason: str, message: str, *args: object) -> bool:
        """Log unless over the limit for `reason`; True when it was logged."""
        now = self._clock()
        self.totals[reason] += 1
        tokens, last = self._bucket.get(reason, (float(self.burst), now))
        tokens = min(float(self.burst), tokens + (now - last) * self.per_minute / 60.0)
        if tokens < 1.0:
            self._bucket[reason] = (tokens, now)
            self._pending[reason] += 1
            self.suppressed[reason] += 1
            return False
        self._bucket[reason] = (tokens - 1.0, now)
        if now - self._reported.get(reason, -60.0) >= 60.0:
            self._report(reason)
            self._reported[reason] = now
        self.logger.warning(message, *args)
        return True

    def _report(self, reason: str, *, final: bool = False) -> None:
        n = self._pending.pop(reason, 0)
        if n:
            self.logger.warning("... and %d more %r warning%s not shown" + (" (%d in all)" if final else ""),
                                n, reason, "" if n == 1 else "s", *([self.totals[reason]] if final else []))

    def flush(self) -> None:
        """Log the count of every warning held back since its reason's last line."""
        for reason in sorted(self._pending):
            self._report(reason, final=True)


def flush_all() -> None:
    """flush() every RateLimitedLog still alive: what a command calls before it exits."""
    for r in sorted(_live, key=id):
        r.flush()
