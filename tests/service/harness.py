"""Run the real service in a thread on a loopback peer, for tests."""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec

from fusion import messages as m
from fusion.config import ServiceConfig, ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port, session_config
from fusion.service import Service
from publishers.spec import load_scenario_file, scenario_path


def scenario_config(name: str) -> tuple[Any, ServiceConfig]:
    sf = load_scenario_file(scenario_path(name))
    return sf.scenario, sf.service


@contextmanager
def running_service(cfg: ServiceConfig, tmp: Path) -> Iterator[tuple[Service, str]]:
    """A started service listening on a free loopback port; stopped (and joined) on exit."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    cfg = msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="peer", listen=[endpoint]))
    svc = Service(cfg, recording_path=tmp / "live.rrd", stream_path=tmp / "live.fstream")
    svc.open()
    t = threading.Thread(target=svc.run, name="service-under-test")
    t.start()
    try:
        yield svc, endpoint
    finally:
        svc.stop()
        t.join(timeout=60)
        assert not t.is_alive(), "the service did not stop"


def run_live(name: str, tmp: Path, *, duration_s: float | None = None, speed: float = 0.0,
             held: Callable[[Any], bool] | None = None
             ) -> tuple[ServiceConfig, list[Any], dict[str, int], list[m.Estimate], Service]:
    """The scenario through the live service, a subscriber collecting the estimates: (service
    config, samples, publisher counts, estimates received, the stopped service). The service's
    stream file is tmp/live.fstream, its recording tmp/live.rrd. With `held`, the samples it
    picks are published after the service has handled all the others (late data whatever the
    machine's speed)."""
    from publishers.stream import build_stream

    spec, cfg = scenario_config(name)
    if duration_s is not None:
        spec = msgspec.structs.replace(spec, duration_s=duration_s)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    with running_service(cfg, tmp) as (svc, endpoint):
        sub_session = client(endpoint)
        try:
            col = EstimateCollector(sub_session, cfg.namespace)
            pub_session = client(endpoint)
            try:
                counts = publish_holding_back(pub_session, svc, samples, held, speed=speed)
            finally:
                pub_session.close()
            assert svc.wait_idle(timeout_s=60.0)
            got = col.all_of(svc)
        finally:
            sub_session.close()
    return cfg, samples, counts, got, svc


def held_back(t_from_ns: int, t_to_ns: int) -> Callable[[Any], bool]:
    """Picks every third measurement (by seq) of sensor time [t_from_ns, t_to_ns): with
    publish_holding_back, late data for the service however fast or busy the machine is (inside
    the 2 s window when the range ends less than 2 s before the stream does)."""

    def held(s: Any) -> bool:
        if "/meas/" not in s.key:
            return False
        meas = m.decode_measurement(s.payload)
        return t_from_ns <= meas.t_ns < t_to_ns and meas.seq % 3 == 0

    return held


def publish_holding_back(session: Any, svc: Service, samples: list[Any], held: Callable[[Any], bool] | None, *,
                         speed: float) -> Counter[str]:
    """publish() the samples; those `held` picks only after the service has handled all the
    others (its wait_idle)."""
    from publishers.publish import publish

    later = [] if held is None else [s for s in samples if held(s)]
    first = samples if not later else [s for s in samples if not held(s)]  # type: ignore[misc]
    counts = publish(session, first, speed=speed, match_timeout_s=5.0)
    if later:
        assert svc.wait_idle(timeout_s=60.0)
        counts += publish(session, later, speed=speed, match_timeout_s=5.0)
    return counts


def client(endpoint: str) -> Any:
    import zenoh

    return zenoh.open(session_config(mode="client", connect=[endpoint]))


class EstimateCollector:
    """Subscribes to fusion/<ns>/tracks/* and keeps every estimate received."""

    def __init__(self, session: Any, ns: str) -> None:
        self.got: list[m.Estimate] = []
        self._lock = threading.Lock()
        self.sub = session.declare_subscriber(m.all_tracks_key(ns), self._cb)
        # A put right after a subscriber is declared elsewhere can miss it (propagation takes
        # up to ~10 ms here); the service's puts have no publisher whose matching status we could
        # wait on, so give the declaration time to arrive.
        time.sleep(0.2)

    def _cb(self, sample: Any) -> None:
        e = m.decode_estimate(sample.payload.to_bytes())
        with self._lock:
            self.got.append(e)

    def snapshot(self) -> list[m.Estimate]:
        with self._lock:
            return list(self.got)

    def all_of(self, svc: Service, *, timeout_s: float = 5.0) -> list[m.Estimate]:
        """Every estimate, once as many arrived as `svc` published (or the timeout passed)."""
        deadline = time.monotonic() + timeout_s
        while len(self.snapshot()) < svc.published and time.monotonic() < deadline:
            time.sleep(0.01)
        return self.snapshot()


def latest(estimates: list[m.Estimate], *, keep_revision: bool = True) -> dict[tuple[int, int, str], m.Estimate]:
    """The consumer's view: latest revision per (track, time, sensor); retractions remove.
    keep_revision=False zeroes the revision: how many times a value was revised depends on
    how arrivals were batched, the final value does not."""
    out: dict[tuple[int, int, str], m.Estimate] = {}
    for e in estimates:
        k = (e.track_id, e.t_ns, e.sensor_id)
        if k in out and out[k].revision > e.revision:
            continue
        if e.status == "retracted":
            out.pop(k, None)
        else:
            out[k] = e
    if not keep_revision:
        out = {k: msgspec.structs.replace(e, revision=0) for k, e in out.items()}
    return out


def rrd_rows(path: Path) -> dict[str, int]:
    """Rows per entity of a recording (static rows not counted)."""
    from collections import Counter

    from rerun.chunk import RrdReader

    rows: Counter[str] = Counter()
    for ch in RrdReader(str(path)).stream():
        if not ch.is_static:
            rows[ch.entity_path] += ch.to_record_batch().num_rows
    return rows


def query(session: Any, key: str) -> bytes:
    replies = list(session.get(key, timeout=5.0))
    assert replies, f"no reply on {key}"
    return replies[0].ok.payload.to_bytes()


class Collector:
    """Subscribes to `key` and keeps every message received, decoded with `decode`."""

    def __init__(self, session: Any, key: str, decode: Any) -> None:
        self.got: list[Any] = []
        self._decode = decode
        self._lock = threading.Lock()
        self.sub = session.declare_subscriber(key, self._cb)
        time.sleep(0.2)  # see EstimateCollector

    def _cb(self, sample: Any) -> None:
        msg = self._decode(sample.payload.to_bytes())
        with self._lock:
            self.got.append(msg)

    def wait_for(self, n: int, *, timeout_s: float = 5.0) -> list[Any]:
        """Every message so far, once at least n arrived (or the timeout passed)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                if len(self.got) >= n:
                    break
            time.sleep(0.01)
        with self._lock:
            return list(self.got)


def put_all(session: Any, samples: list[tuple[str, bytes]], *, pause_s: float = 0.0) -> None:
    """Put (key, payload) in order, each key through a publisher the service is matched with,
    pause_s apart."""
    import zenoh

    pubs: dict[str, Any] = {}
    try:
        for key, payload in samples:
            if key not in pubs:
                pubs[key] = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                deadline = time.monotonic() + 5
                while not pubs[key].matching_status.matching and time.monotonic() < deadline:
                    time.sleep(0.001)
            pubs[key].put(payload)
            if pause_s:
                time.sleep(pause_s)
    finally:
        for p in pubs.values():
            p.undeclare()
