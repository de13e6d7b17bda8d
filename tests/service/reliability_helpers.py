"""The real service in a thread for the reliability tests: started at once or when the test
says (samples then wait in the intake queue, as behind a stalled tracker), with any outputs."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import msgspec

from fusion import messages as m
from fusion.config import ServiceConfig, ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port
from fusion.service import Service
from tests.service.harness import query


@contextmanager
def service_thread(cfg: ServiceConfig, *, started: bool = True,
                   **outputs: Any) -> Iterator[tuple[Service, str, Callable[[], None]]]:
    """(service, endpoint, start): a peer on a free loopback port, opened; its loop runs at once
    (started) or when start() is called. `outputs`: Service's recording_dir / recording_path /
    stream_path. Stopped and joined on exit."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    svc = Service(msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="peer", listen=[endpoint])), **outputs)
    svc.open()
    t = threading.Thread(target=svc.run, name="service-under-test")
    if started:
        t.start()
    try:
        yield svc, endpoint, t.start
    finally:
        svc.stop()
        if t.is_alive():
            t.join(timeout=60)
        else:
            svc.shutdown()
        assert not t.is_alive(), "the service did not stop"


def publisher(s: Any, key: str) -> Any:
    """A BLOCK publisher on `key`, once the service's subscriber matches it."""
    import zenoh

    p = s.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 5
    while not p.matching_status.matching and time.monotonic() < deadline:
        time.sleep(0.001)
    return p


def wait_offered(svc: Service, n: int, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while svc.intake.offered < n and time.monotonic() < deadline:
        time.sleep(0.005)
    assert svc.intake.offered == n, f"{svc.intake.offered} of {n} samples arrived"


def settled_status(svc: Service, s: Any, ns: str) -> m.ServiceStatus:
    """The status once every sample is handled (and the answer refreshed)."""
    assert svc.wait_idle(timeout_s=30.0)
    time.sleep(0.15)  # the loop refreshes its answers every 0.1 s
    return m.decode_status(query(s, m.status_key(ns)))
