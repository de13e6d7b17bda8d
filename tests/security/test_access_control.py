"""Zenoh access control on the real service (mutual TLS, identities by certificate common name):
sensors may only publish their own measurements, consumers may only read tracks and query
status and snapshot, and nobody but the service can publish estimates or answer its queries.

The forged-estimate and rogue-queryable cases run once without access control as the control:
there the forgeries get through (what the hostile-client probe of issue 13 found)."""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import pytest

from fusion import messages as m
from fusion.config import AccessControlConfig, ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port, wait_for_match, zenoh_json
from publishers.publish import publish
from publishers.stream import build_stream
from tests.security.conftest import Certs, cam1_measurement, lossy_client, service_zenoh, tls_service
from tests.service.harness import scenario_config

ACL = AccessControlConfig(sensors={"cam1": ["sensor-cam1"], "radar1": ["sensor-radar1"]}, simulators=["simulator"],
                          consumers=["viewer"], recorders=["recorder"])
PROPAGATION_S = 0.3  # generous time for a declaration or a put to cross the hub on this busy machine


class Collector:
    """A subscriber keeping (key, payload) of every sample."""

    def __init__(self, session: Any, key: str) -> None:
        self.got: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self.sub = session.declare_subscriber(key, self._cb)

    def _cb(self, sample: Any) -> None:
        with self._lock:
            self.got.append((str(sample.key_expr), sample.payload.to_bytes()))

    def key_list(self) -> list[str]:
        with self._lock:
            return [k for k, _ in self.got]


def _replies(session: Any, key: str) -> list[bytes]:
    """Every reply to a query on `key`, from every queryable (target ALL, consolidation NONE: the
    default keeps one reply per key, the latest, so that of two queryables on the same key one
    answer was dropped, which one by timing). A query nobody may answer gets no reply and ends at
    the timeout."""
    import zenoh

    return [r.ok.payload.to_bytes() for r in session.get(key, target=zenoh.QueryTarget.ALL,
                                                         consolidation=zenoh.ConsolidationMode.NONE, timeout=0.5)
            if r.ok is not None]


def _mix(duration_s: float) -> tuple[Any, list[Any]]:
    spec, cfg = scenario_config("mix")
    samples, _ = build_stream(msgspec.structs.replace(spec, duration_s=duration_s), namespace=cfg.namespace)
    return cfg, samples


@pytest.mark.parametrize("acl", [ACL, None], ids=["access control", "control: TLS only"])
def test_sensor_cannot_forge_estimates_answer_queries_or_read_the_snapshot(
        acl: AccessControlConfig | None, certs: Certs, tmp_path: Path, tls_client: Callable[..., Any]) -> None:
    cfg, samples = _mix(3.0)
    ns = cfg.namespace
    with tls_service(cfg, certs, tmp_path, access_control=acl) as (svc, endpoint):
        viewer = tls_client(endpoint, certs.tls("viewer"))
        tracks = Collector(viewer, m.all_tracks_key(ns))
        cam = tls_client(endpoint, certs.tls("sensor-cam1"))
        rogue = [cam.declare_queryable(k, lambda q: q.reply(q.key_expr, b"forged"))
                 for k in (m.status_key(ns), m.snapshot_key(ns))]
        time.sleep(PROPAGATION_S)
        cam.put(m.track_key(ns, 999), b"forged")
        publish(tls_client(endpoint, certs.tls("simulator")), samples, speed=0.0, match_timeout_s=5.0)
        assert svc.wait_idle(timeout_s=60.0)
        deadline = time.monotonic() + 5.0
        while len(tracks.key_list()) < svc.published + (acl is None) and time.monotonic() < deadline:
            time.sleep(0.01)
        status = _replies(viewer, m.status_key(ns))
        snapshot = _replies(viewer, m.snapshot_key(ns))
        for q in rogue:  # (a session answers its own queries: the sensor asks once they are gone)
            q.undeclare()
        cam_snapshot = _replies(cam, m.snapshot_key(ns))
    forged_track = m.track_key(ns, 999)
    assert svc.published > 0
    if acl is None:  # the control: without access control every forgery is delivered
        assert forged_track in tracks.key_list()
        assert b"forged" in status and b"forged" in snapshot
        assert len(status) == 2 and len(snapshot) == 2, "the service answers beside the forger"
        assert cam_snapshot
        return
    assert forged_track not in tracks.key_list()
    assert len(tracks.key_list()) == svc.published, "the consumer gets every estimate of the service and nothing else"
    assert len(status) == 1 and m.decode_status(status[0]).counts.received > 0
    assert len(snapshot) == 1 and m.decode_snapshot(snapshot[0]).estimates
    assert cam_snapshot == [], "a sensor read the snapshot"


def test_sensor_publishes_its_own_measurements_only(certs: Certs, tmp_path: Path,
                                                    tls_client: Callable[..., Any]) -> None:
    cfg, samples = _mix(3.0)
    ns = cfg.namespace
    own = [s for s in samples if s.key == m.meas_key(ns, "cam1")]
    other = [s for s in samples if s.key == m.meas_key(ns, "radar1")]
    assert own and other
    with tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        cam = tls_client(endpoint, certs.tls("sensor-cam1"))
        pub = cam.declare_publisher(m.meas_key(ns, "cam1"))
        assert wait_for_match(pub, timeout_s=5.0), "the sensor does not see the service's subscription"
        for s in other:  # radar1's measurements, on radar1's key, from cam1's identity
            cam.put(s.key, s.payload)
        for s in own:  # cam1's own payloads on radar1's key: the key/payload mismatch of issue 13
            cam.put(m.meas_key(ns, "radar1"), s.payload)
        cam.put(m.truth_key(ns, "x"), b"truth from a sensor")
        for s in own:
            pub.put(s.payload)
        assert svc.wait_idle(timeout_s=30.0)
        counts = svc.status_dict()["counts"]
        status_by_sensor = _replies(cam, m.status_key(ns))
    assert counts["received"] == len(own), "only cam1's own key reached the service"
    assert counts["applied"] + counts["duplicates"] == len(own)
    assert status_by_sensor == [], "a sensor queried the status"


def test_only_sensors_and_simulators_publish_measurements(certs: Certs, tmp_path: Path,
                                                          tls_client: Callable[..., Any]) -> None:
    """A consumer, a recorder and a certified stranger put every sample of a scenario: none
    reaches the service. Then a simulator publishes it: all of it arrives, and of the three
    only the recorder sees it."""
    cfg, samples = _mix(2.0)
    ns = cfg.namespace
    meas = [s for s in samples if "/meas/" in s.key]
    who = ("viewer", "recorder", "stranger")
    with tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        sessions = {w: tls_client(endpoint, certs.tls(w)) for w in who}
        for s in sessions.values():
            for x in samples:
                s.put(x.key, x.payload)
        time.sleep(PROPAGATION_S)
        refused_received = svc.status_dict()["counts"]["received"]
        seen = {w: Collector(s, m.all_meas_key(ns)) for w, s in sessions.items()}
        time.sleep(PROPAGATION_S)
        publish(tls_client(endpoint, certs.tls("simulator")), samples, speed=0.0, match_timeout_s=5.0)
        assert svc.wait_idle(timeout_s=30.0)
        received = svc.status_dict()["counts"]["received"]
        deadline = time.monotonic() + 5.0
        while len(seen["recorder"].key_list()) < len(meas) and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(PROPAGATION_S)
    assert refused_received == 0, "a consumer, recorder or stranger published measurements"
    assert received == len(samples)  # measurements and truth
    assert {w: len(c.key_list()) for w, c in seen.items()} == {"viewer": 0, "recorder": len(meas), "stranger": 0}


def test_ingress_filter_holds_when_the_sensor_sees_every_subscription(certs: Certs,
                                                                      tls_client: Callable[..., Any]) -> None:
    """Defence in depth: even where the hub tells a sensor of every subscription (so its
    publisher matches and its client sends), the hub drops the sensor's put on a tracks key."""
    import zenoh

    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    conf = zenoh_json(service_zenoh(certs, endpoint, access_control=ACL), namespace="demo")
    ac = conf["access_control"]
    ac["rules"].append({"id": "see-all", "messages": ["declare_subscriber"], "flows": ["egress"],
                        "permission": "allow", "key_exprs": ["**"]})
    next(p for p in ac["policies"] if p["id"] == "sensor-cam1")["rules"].append("see-all")
    with zenoh.open(zenoh.Config.from_json5(json.dumps(conf))) as hub:
        got = Collector(hub, "fusion/demo/**")
        cam = tls_client(endpoint, certs.tls("sensor-cam1"))
        forged = cam.declare_publisher(m.track_key("demo", 1))
        own = cam.declare_publisher(m.meas_key("demo", "cam1"))
        assert wait_for_match(forged, timeout_s=5.0) and wait_for_match(own, timeout_s=5.0)
        forged.put(b"forged")
        own.put(b"measurement")
        deadline = time.monotonic() + 5.0
        while not got.key_list() and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(PROPAGATION_S)
        assert got.key_list() == [m.meas_key("demo", "cam1")]


def test_profile_on_a_router_with_the_service_as_a_client(certs: Certs, tmp_path: Path,
                                                          tls_client: Callable[..., Any],
                                                          caplog: pytest.LogCaptureFixture) -> None:
    """The same rules on a zenoh router (here an in-process Python one) that the service joins as
    a client with the `services` identity: the service gets measurements and publishes tracks,
    a sensor still can neither forge estimates nor answer status queries. The service's advanced
    subscriber is announced through the router (its liveliness token is granted), so the
    simulator's publishers see it at once instead of waiting out their match timeout."""
    import zenoh

    from fusion.service import Service

    cfg, samples = _mix(3.0)
    ns = cfg.namespace
    acl = msgspec.structs.replace(ACL, services=["fusion-service"])
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    conf = zenoh_json(service_zenoh(certs, endpoint, access_control=acl), namespace=ns)
    conf["mode"] = "router"
    with zenoh.open(zenoh.Config.from_json5(json.dumps(conf))):
        zc = ZenohConfig(mode="client", listen=[], connect=[endpoint], tls=certs.tls("fusion-service"))
        svc = Service(msgspec.structs.replace(cfg, zenoh=zc), recording_path=tmp_path / "r.rrd",
                      stream_path=tmp_path / "r.fstream")
        svc.open()
        runner = threading.Thread(target=svc.run, name="service-behind-router")
        runner.start()
        try:
            viewer = tls_client(endpoint, certs.tls("viewer"))
            tracks = Collector(viewer, m.all_tracks_key(ns))
            cam = tls_client(endpoint, certs.tls("sensor-cam1"))
            rogue = cam.declare_queryable(m.status_key(ns), lambda q: q.reply(q.key_expr, b"forged"))
            time.sleep(PROPAGATION_S)
            cam.put(m.track_key(ns, 999), b"forged")
            with caplog.at_level(logging.WARNING, logger="publishers"):
                publish(tls_client(endpoint, certs.tls("simulator")), samples, speed=0.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=60.0)
            deadline = time.monotonic() + 5.0
            while len(tracks.key_list()) < svc.published and time.monotonic() < deadline:
                time.sleep(0.01)
            time.sleep(PROPAGATION_S)
            status = _replies(viewer, m.status_key(ns))
            rogue.undeclare()
            received = svc.status_dict()["counts"]["received"]
        finally:
            svc.stop()
            runner.join(timeout=60)
    assert received == len(samples)  # measurements and truth
    assert svc.published > 0 and len(tracks.key_list()) == svc.published
    assert m.track_key(ns, 999) not in tracks.key_list()
    assert len(status) == 1 and m.decode_status(status[0]).counts.received == received
    assert not [r for r in caplog.records if "no subscriber matched" in r.message]


def test_a_sensors_dropped_measurements_are_recovered_under_access_control(certs: Certs, tmp_path: Path) -> None:
    """Zenoh's advanced publisher under the sensor role: cam1's seq 3, 4 and 9 are dropped as
    they leave it (a low-pass filter on its session); the service recovers all three from its
    cache (a hole, then the heartbeat for the last one), and cam1 still may not publish for
    radar1 nor query the status."""
    from fusion.io.zenoh_advanced import declare_recoverable_publisher, wait_for_recovering_subscriber

    cfg, _ = _mix(1.0)
    ns = cfg.namespace
    cam1 = cam1_measurement
    with tls_service(cfg, certs, tmp_path, access_control=ACL) as (svc, endpoint):
        cam = lossy_client(certs, endpoint, "sensor-cam1", ns)
        try:
            pub = declare_recoverable_publisher(cam, m.meas_key(ns, "cam1"), cache_samples=100, heartbeat_s=0.1)
            assert wait_for_recovering_subscriber(cam, m.meas_key(ns, "cam1"), timeout_s=5.0)
            time.sleep(PROPAGATION_S)  # the publisher's cache queryable must reach the service first
            for seq in range(10):
                pub.put(cam1(seq, big=seq in (3, 4, 9)))
            deadline = time.monotonic() + 10.0
            while svc.status_dict()["counts"]["applied"] < 10 and time.monotonic() < deadline:
                time.sleep(0.02)
            cam.put(m.meas_key(ns, "radar1"), cam1(20))
            status_by_sensor = _replies(cam, m.status_key(ns))
            assert svc.wait_idle(timeout_s=30.0)
            st = svc.status_dict()
            pub.undeclare()
        finally:
            cam.close()
    assert st["counts"]["received"] == st["counts"]["applied"] == 10, (st["counts"], st["gaps"])
    assert st["gaps"]["cam1"]["missing"] == 0 and "zenoh_missed" not in st["gaps"]["cam1"], st["gaps"]
    assert status_by_sensor == []
