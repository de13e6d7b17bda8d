"""KeyedPublishers over real Zenoh sessions on loopback: every put arrives on its key, one
publisher per key is declared and reused, retire/close undeclare them, the bound holds."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from fusion.io.zenoh_publishers import KeyedPublishers


def _collect(session: Any, key: str) -> tuple[list[tuple[str, bytes]], threading.Lock, Any]:
    got: list[tuple[str, bytes]] = []
    lock = threading.Lock()

    def on(sample: Any) -> None:
        with lock:
            got.append((str(sample.key_expr), sample.payload.to_bytes()))

    return got, lock, session.declare_subscriber(key, on)


def _wait(got: list[Any], lock: threading.Lock, n: int, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with lock:
            if len(got) >= n:
                return
        time.sleep(0.01)


def test_puts_arrive_on_their_keys_through_one_publisher_per_key(zenoh_hub: tuple[Any, str],
                                                                 zenoh_client: Callable[[], Any]) -> None:
    hub, _ = zenoh_hub
    sub_session = zenoh_client()
    got, lock, sub = _collect(sub_session, "t/tracks/*")
    try:
        time.sleep(0.3)  # the subscriber's declaration reaches the hub
        pubs = KeyedPublishers(hub, lambda k: f"t/tracks/{k}", congestion_control=zenoh.CongestionControl.BLOCK)
        sent = [(k, f"{k}-{i}".encode()) for i in range(5) for k in (3, 1, 2)]
        for k, p in sent:
            pubs.put(k, p)
        assert pubs.declared == 3 and len(pubs) == 3
        _wait(got, lock, len(sent))
        with lock:
            assert sorted(got) == sorted((f"t/tracks/{k}", p) for k, p in sent)
            for k in (1, 2, 3):  # per key, in the order put
                assert [p for key, p in got if key == f"t/tracks/{k}"] == [p for kk, p in sent if kk == k]
        pubs.retire({1, 2})
        assert len(pubs) == 2
        pubs.put(3, b"again")  # a retired key gets a new publisher
        assert pubs.declared == 4
        _wait(got, lock, len(sent) + 1)
        with lock:
            assert got[-1] == ("t/tracks/3", b"again")
        pubs.close()
        assert len(pubs) == 0
    finally:
        sub.undeclare()


def test_the_bound_undeclares_before_declaring_more(zenoh_hub: tuple[Any, str]) -> None:
    hub, _ = zenoh_hub
    pubs = KeyedPublishers(hub, lambda k: f"t/b/{k}", congestion_control=zenoh.CongestionControl.BLOCK,
                           max_publishers=4)
    for k in range(10):
        pubs.put(k, b"x")
        assert len(pubs) <= 4
    assert pubs.declared == 10
    pubs.close()
