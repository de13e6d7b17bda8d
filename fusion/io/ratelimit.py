"""Rate-limited warnings: a flood of bad input cannot fill the disk with log lines."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable


class RateLimitedLog:
    """At most `per_minute` warnings per reason in any rolling minute; the rest are counted and
    summarised ("... and N more like it") when the minute is over."""

    def __init__(self, logger: logging.Logger, *, per_minute: int = 60,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.per_minute = per_minute
        self._clock = clock
        self._window: dict[str, tuple[float, int, int]] = {}  # reason -> (start, emitted, suppressed)

    def warn(self, reason: str, message: str, *args: object) -> bool:
        """Log unless over the limit for `reason`; True when it was logged."""
        now = self._clock()
        start, emitted, suppressed = self._window.get(reason, (now, 0, 0))
        if now - start >= 60.0:
            if suppressed:
                self.logger.warning("%d more %s warnings suppressed in the last minute", suppressed, reason)
            start, emitted, suppressed = now, 0, 0
        if emitted < self.per_minute:
            self.logger.warning(message, *args)
            self._window[reason] = (start, emitted + 1, suppressed)
            return True
        self._window[reason] = (start, emitted, suppressed + 1)
        return False
