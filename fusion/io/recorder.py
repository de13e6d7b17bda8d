"""`fusion record`: every measurement, control input and truth sample on a namespace, with its
arrival time, into a stream file (fusion.io.streamfile), so that `fusion replay` runs what the
service ran (before, inputs were not recorded, and a replay of a stream with control inputs
predicted without them). Callbacks only enqueue; one thread writes.

Measurements and inputs come through the service's kind of subscription
(fusion.io.zenoh_advanced): a publisher (publishers.publish) sees it announced and starts at once
(with a plain subscriber it waited its whole match timeout, 10 s, and warned that no subscriber
matched); a sample the network dropped is recovered from the publisher's cache; and a recorder
started after a publisher first gets what that cache still holds (fusion-publish keeps 1 000),
stamped with the time they reach the recorder: the stream a service joining at that moment sees."""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path
from typing import Any

from fusion import messages as m
from fusion.io.streamfile import StreamWriter
from fusion.io.zenoh_advanced import RecoveringSubscription


class Recorder:
    """Subscribes on `session` to fusion/<ns>/meas/*, input/* and truth/*; `close()` drains and closes."""

    def __init__(self, session: Any, path: str | Path, *, namespace: str) -> None:
        self._q: queue.SimpleQueue[tuple[int, str, bytes] | None] = queue.SimpleQueue()
        self.writer = StreamWriter(path, namespace=namespace)
        self._thread = threading.Thread(target=self._write, name="fusion-recorder", daemon=True)
        self._thread.start()
        cb = self._on_sample
        self._recovering = {"meas": RecoveringSubscription(session, m.all_meas_key(namespace), cb),
                            "input": RecoveringSubscription(session, m.all_input_key(namespace), cb)}
        self._subs = [*self._recovering.values(), session.declare_subscriber(m.all_truth_key(namespace), cb)]

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

    def missed(self) -> dict[str, int]:
        """Measurements and inputs zenoh reported lost and not recovered, by "meas/<sensor>" and
        "input/<source>" (none, usually)."""
        return dict(sorted((f"{kind}/{k}", n) for kind, sub in self._recovering.items()
                           for k, n in sub.missed().items()))

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()
        self._subs = []
        self._q.put(None)
        self._thread.join()
        self.writer.close()
