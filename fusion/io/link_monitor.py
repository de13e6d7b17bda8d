"""The service's Zenoh link: retry with backoff at start, and whether it is up now.

`open_with_retry(zenoh, conf, retry_s=..., stop=...)`: a client whose router or peer is not up
yet retries `zenoh.open` with exponential backoff (0.25 s doubling to 5 s) for up to `retry_s`
seconds, logging each wait, and raises the last error after that (or at once when retry_s is
0, or when `stop` is set). `LinkMonitor(session)`: `poll()` (every `interval_s` at most) reads
the session's routers and peers; the status says whether the service is connected, how many
links it has, and how many times it lost and regained them (zenoh reconnects on its own).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

log = logging.getLogger("fusion.zenoh")


def open_with_retry(zenoh: Any, conf: Any, *, retry_s: float, stop: threading.Event | None = None) -> tuple[Any, int]:
    """(session, attempts); see the module docstring."""
    deadline = time.monotonic() + retry_s
    wait, attempts = 0.25, 0
    while True:
        attempts += 1
        try:
            return zenoh.open(conf), attempts
        except Exception as e:  # zenoh raises ZError; only "cannot connect" is worth a retry
            if "Unable to connect" not in str(e) or time.monotonic() + wait > deadline or (stop and stop.is_set()):
                raise
            log.warning("zenoh: nothing to connect to yet (attempt %d); retrying in %.2f s for up to %.0f s more",
                        attempts, wait, deadline - time.monotonic())
            if stop is not None:
                stop.wait(wait)
            else:
                time.sleep(wait)
            wait = min(wait * 2, 5.0)


class LinkMonitor:
    """See the module docstring."""

    def __init__(self, session: Any, *, attempts: int = 1, interval_s: float = 0.5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.session = session
        self.connect_attempts = attempts
        self.interval_s = interval_s
        self._clock = clock
        self._at = -1e9
        self.links = 0
        self.connected = True
        self.disconnects = 0
        self.reconnects = 0

    def poll(self) -> None:
        now = self._clock()
        if now - self._at < self.interval_s:
            return
        self._at = now
        info = self.session.info
        n = len(list(info.routers_zid())) + len(list(info.peers_zid()))
        up = n > 0
        if up and not self.connected:
            self.reconnects += 1
            log.warning("zenoh: connected again (%d link%s)", n, "" if n == 1 else "s")
        elif self.connected and not up:
            self.disconnects += 1
            log.warning("zenoh: lost every link; zenoh keeps trying to reconnect")
        self.links, self.connected = n, up

    def status(self) -> dict[str, Any]:
        return {"connected": self.connected, "links": self.links, "disconnects": self.disconnects,
                "reconnects": self.reconnects, "connect_attempts": self.connect_attempts}
