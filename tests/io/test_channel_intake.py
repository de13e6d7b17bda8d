"""ChannelIntake over real Zenoh sessions on loopback: every sample reaches `take` once, in the
order put, stamped with nondecreasing times, in chunks while `take` is busy; an undeclared
subscriber's channel is emptied before its thread ends; an exception from `take` is logged and
kept, and later samples still arrive."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import pytest
import zenoh

from fusion.io.channel_intake import ChannelIntake, Taken
from tests.service.reliability_helpers import publisher


class Recorder:
    """A `take` that keeps what it is given; `gate` (when cleared) holds it, as a busy loop does."""

    def __init__(self) -> None:
        self.chunks: list[Taken] = []
        self.lock = threading.Lock()
        self.gate = threading.Event()
        self.gate.set()
        self.entered = threading.Event()

    def __call__(self, taken: Taken) -> None:
        self.entered.set()
        self.gate.wait(10.0)
        with self.lock:
            self.chunks.append(taken)

    def payloads(self) -> list[bytes]:
        with self.lock:
            return [s.payload.to_bytes() for chunk in self.chunks for _, s in chunk]

    def wait_for(self, n: int, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while len(self.payloads()) < n and time.monotonic() < deadline:
            time.sleep(0.005)


def test_every_sample_once_in_order_and_in_chunks_while_take_is_busy(
        zenoh_hub: tuple[Any, str], zenoh_client: Callable[[], Any]) -> None:
    hub, _ = zenoh_hub
    sub = hub.declare_subscriber("ci/meas/*", zenoh.handlers.FifoChannel(4096))
    rec = Recorder()
    intake = ChannelIntake([sub.handler], rec, chunk=100)
    try:
        pub = publisher(zenoh_client(), "ci/meas/a")
        pub.put(b"first")
        assert rec.entered.wait(5.0)
        rec.gate.clear()  # take is busy: the next samples wait in the channel
        rec.wait_for(1)
        sent = [f"{i}".encode() for i in range(500)]
        for p in sent:
            pub.put(p)
        time.sleep(0.3)
        rec.gate.set()
        rec.wait_for(501)
        assert rec.payloads() == [b"first", *sent]  # each once, in the order put
        with rec.lock:
            stamps = [a for chunk in rec.chunks for a, _ in chunk]
            sizes = [len(c) for c in rec.chunks]
        assert stamps == sorted(stamps)
        assert max(sizes) == 100  # what waited came in chunks of at most `chunk`
    finally:
        sub.undeclare()
        assert intake.join()


def test_an_undeclared_subscriber_s_channel_is_emptied_before_its_thread_ends(
        zenoh_hub: tuple[Any, str], zenoh_client: Callable[[], Any]) -> None:
    hub, _ = zenoh_hub
    subs = [hub.declare_subscriber(f"ci/{k}/*", zenoh.handlers.FifoChannel(4096)) for k in ("m", "t")]
    rec = Recorder()
    intake = ChannelIntake([s.handler for s in subs], rec)
    client = zenoh_client()
    pm, pt = publisher(client, "ci/m/x"), publisher(client, "ci/t/y")
    pm.put(b"m-first")
    assert rec.entered.wait(5.0)
    rec.gate.clear()
    rec.wait_for(1)
    for i in range(50):
        pm.put(f"m{i}".encode())
        pt.put(f"t{i}".encode())
    time.sleep(0.3)  # all of it in the channels (or in take's hands)
    for s in subs:
        s.undeclare()
    rec.gate.set()
    assert intake.join(5.0)  # both threads ended, after taking what their channels held
    got = rec.payloads()
    assert sorted(got) == sorted([b"m-first"] + [f"{k}{i}".encode() for i in range(50) for k in "mt"])
    assert [p for p in got if p.startswith(b"t")] == [f"t{i}".encode() for i in range(50)]  # per channel, in order


def test_an_exception_from_take_is_logged_and_later_samples_still_arrive(
        zenoh_hub: tuple[Any, str], zenoh_client: Callable[[], Any], caplog: pytest.LogCaptureFixture) -> None:
    hub, _ = zenoh_hub
    sub = hub.declare_subscriber("ci/e/*", zenoh.handlers.FifoChannel(64))
    got: list[bytes] = []

    def take(taken: Taken) -> None:
        for _, s in taken:
            p = s.payload.to_bytes()
            if p == b"bad":
                raise ValueError("a bug in take")
            got.append(p)

    intake = ChannelIntake([sub.handler], take)
    try:
        pub = publisher(zenoh_client(), "ci/e/a")
        with caplog.at_level(logging.ERROR, logger="fusion.intake"):
            pub.put(b"bad")
            deadline = time.monotonic() + 5.0
            while not intake.errors and time.monotonic() < deadline:
                time.sleep(0.005)
            pub.put(b"good")
            while not got and time.monotonic() < deadline:
                time.sleep(0.005)
        assert got == [b"good"]
        assert [type(e) for e in intake.errors] == [ValueError]
        assert any("samples from a Zenoh channel lost" in r.getMessage() for r in caplog.records)
    finally:
        sub.undeclare()
        assert intake.join()
