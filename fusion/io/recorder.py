"""`fusion record`: every measurement and truth sample on a namespace, with its arrival time,
into a stream file (fusion.io.streamfile). Callbacks only enqueue; one thread writes."""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path
from typing import Any

from fusion import messages as m
from fusion.io.streamfile import StreamWriter


class Recorder:
    """Subscribes on `session` to fusion/<ns>/meas/* and truth/*; `close()` drains and closes."""

    def __init__(self, session: Any, path: str | Path, *, namespace: str) -> None:
        self._q: queue.SimpleQueue[tuple[int, str, bytes] | None] = queue.SimpleQueue()
        self.writer = StreamWriter(path, namespace=namespace)
        self._thread = threading.Thread(target=self._write, name="fusion-recorder", daemon=True)
        self._thread.start()
        cb = self._on_sample
        self._subs = [session.declare_subscriber(m.all_meas_key(namespace), cb),
                      session.declare_subscriber(m.all_truth_key(namespace), cb)]

    def _on_sample(self, sample: Any) -> None:
        self._q.put((time.time_ns(), str(sample.key_expr), sample.payload.to_bytes()))

    def _write(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            self.writer.write(*item)

    @property
    def records(self) -> int:
        return self.writer.records

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self._subs = []
        self._q.put(None)
        self._thread.join()
        self.writer.close()
