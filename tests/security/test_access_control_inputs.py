"""Control inputs and `fusion record` under access control (mutual TLS, identities by certificate
common name): an input source may put its own inputs only, a simulator may put inputs beside
measurements and truth, and a recorder gets everything a service gets, inputs included, with
zenoh's advanced subscriber working as it does for the service (history on joining, recovery of
a dropped sample). Before, no role covered fusion/NS/input/*, so inputs were dropped, and the
recorder's role had no grant for the advanced subscriber's exchanges, so it recovered nothing."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.config import AccessControlConfig
from fusion.io.recorder import Recorder
from fusion.io.streamfile import StreamReader
from fusion.io.zenoh_advanced import declare_recoverable_publisher, wait_for_recovering_subscriber
from publishers.publish import publish
from publishers.stream import CONTROL_SOURCE, build_stream
from tests.security.conftest import Certs, cam1_measurement, lossy_client, tls_service
from tests.service.harness import scenario_config

ACL = AccessControlConfig(sensors={"cam1": ["sensor-cam1"]}, inputs={CONTROL_SOURCE: ["input-control"]},
                          simulators=["simulator"], consumers=["viewer"], recorders=["recorder"])
PROPAGATION_S = 0.3  # generous time for a declaration or a put to cross the hub on this busy machine


def _wait(cond: Callable[[], bool], timeout_s: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.01)
    return cond()


def _cv1d_d() -> tuple[Any, list[Any]]:
    spec, cfg = scenario_config("cv1d_d")
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    return cfg, samples


def _recorded(path: Path) -> list[tuple[str, bytes]]:
    return sorted((k, p) for _, k, p in StreamReader(path))


def test_a_simulators_inputs_reach_the_service_and_the_recorder(certs: Certs, tmp_path: Path,
                                                              tls_client: Callable[..., Any],
                                                              caplog: pytest.LogCaptureFixture) -> None:
    cfg, samples = _cv1d_d()
    ns = cfg.namespace
    inputs = [s for s in samples if "/input/" in s.key]
    assert inputs and len(inputs) < len(samples)
    with tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        rec = Recorder(tls_client(endpoint, certs.tls("recorder")), tmp_path / "in.fstream", namespace=ns)
        try:
            time.sleep(PROPAGATION_S)
            with caplog.at_level(logging.WARNING, logger="publishers"):
                publish(tls_client(endpoint, certs.tls("simulator")), samples, speed=0.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=60.0)
            counts = svc.status_dict()["counts"]
            assert _wait(lambda: rec.records >= len(samples)), (rec.records, len(samples))
            missed = rec.missed()
        finally:
            rec.close()
    # the publisher saw the service's and the recorder's subscriptions at once: no timeout waited out
    assert not [r for r in caplog.records if "no subscriber matched" in r.message]
    assert counts["received"] == len(samples) and counts["inputs"] == len(inputs), counts
    assert missed == {}
    assert _recorded(tmp_path / "in.fstream") == sorted((s.key, s.payload) for s in samples)


def test_an_input_source_puts_its_own_inputs_only(certs: Certs, tmp_path: Path,
                                                  tls_client: Callable[..., Any]) -> None:
    """The control source's identity publishes its inputs through zenoh's advanced publisher,
    as fusion-publish does (it sees the service's subscriber, its inputs arrive); the same
    payloads on another source's key, a measurement and a truth sample from it are dropped."""
    cfg, samples = _cv1d_d()
    ns = cfg.namespace
    own = [s for s in samples if s.key == m.input_key(ns, CONTROL_SOURCE)]
    meas = next(s for s in samples if "/meas/" in s.key)
    with tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        src = tls_client(endpoint, certs.tls("input-control"))
        pub = declare_recoverable_publisher(src, m.input_key(ns, CONTROL_SOURCE))
        try:
            assert wait_for_recovering_subscriber(src, m.input_key(ns, CONTROL_SOURCE), timeout_s=5.0), \
                "the input source does not see the service's subscriber"
            for s in own[:5]:
                src.put(m.input_key(ns, "other"), s.payload)
            src.put(meas.key, meas.payload)
            src.put(m.truth_key(ns, "x"), b"truth from an input source")
            time.sleep(PROPAGATION_S)
            for s in own:
                pub.put(s.payload)
            assert _wait(lambda: svc.status_dict()["counts"]["received"] >= len(own))
            time.sleep(PROPAGATION_S)
            assert svc.wait_idle(timeout_s=30.0)
            counts = svc.status_dict()["counts"]
        finally:
            pub.undeclare()
    assert counts["received"] == counts["inputs"] == len(own), counts


def test_a_recorder_gets_the_history_and_recovers_a_dropped_sample(certs: Certs, tmp_path: Path,
                                                                   tls_client: Callable[..., Any],
                                                                   caplog: pytest.LogCaptureFixture) -> None:
    """cam1 puts 5 measurements, then a recorder joins: it gets them from cam1's cache (the
    advanced subscriber's history). cam1 then puts 5 more, of which seq 7 and the last are
    dropped as they leave it (a low-pass filter on its session): the recorder recovers both, as
    the service does, and reports nothing missed. The service, whose tracker here has no control
    source, says at start that the grant for one is not its own (fusion.io.zenoh_acl.mismatches)."""
    cfg, _ = _cv1d_d()
    ns = cfg.namespace
    cfg = msgspec.structs.replace(cfg, tracker=scenario_config("mix")[1].tracker)  # a tracker with cam1
    cam1 = cam1_measurement
    with caplog.at_level(logging.WARNING, logger="fusion.service"), \
            tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        said = [r.getMessage() for r in caplog.records if r.name == "fusion.service"]
        assert ("access control: zenoh.access_control.inputs grants 'control', which is not the tracker's control "
                "source (it has none): the service ignores its inputs") in said, said
        cam = lossy_client(certs, endpoint, "sensor-cam1", ns)
        rec = None
        try:
            pub = declare_recoverable_publisher(cam, m.meas_key(ns, "cam1"), cache_samples=100, heartbeat_s=0.1)
            assert wait_for_recovering_subscriber(cam, m.meas_key(ns, "cam1"), timeout_s=5.0)
            time.sleep(PROPAGATION_S)
            for seq in range(5):
                pub.put(cam1(seq))
            assert _wait(lambda: svc.status_dict()["counts"]["received"] >= 5)
            rec = Recorder(tls_client(endpoint, certs.tls("recorder")), tmp_path / "in.fstream", namespace=ns)
            assert _wait(lambda: rec is not None and rec.records >= 5), "the recorder did not get cam1's history"
            time.sleep(PROPAGATION_S)
            for seq in range(5, 10):
                pub.put(cam1(seq, big=seq in (7, 9)))
            assert _wait(lambda: rec is not None and rec.records >= 10), rec.records
            assert _wait(lambda: svc.status_dict()["counts"]["received"] >= 10)
            missed = rec.missed()
            pub.undeclare()
        finally:
            if rec is not None:
                rec.close()
            cam.close()
    assert missed == {}
    got = _recorded(tmp_path / "in.fstream")
    assert sorted(m.decode_measurement(p).seq for _, p in got) == list(range(10)), "each sample once"
