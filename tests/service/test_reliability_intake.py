"""The intake bounds and fairness through a real zenoh client against the service: a byte limit
before decoding, a queue bounded in samples and bytes on every key, one sensor's flood costing
only that sensor, and the counts adding up (received = applied + truth + duplicates +
sum(refused by reason) + queued)."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import msgspec

from fusion import messages as m
from fusion.cli.report import counts_line
from fusion.config import IntakeConfig, ServiceConfig
from tests.service.harness import EstimateCollector, client, scenario_config
from tests.service.reliability_helpers import publisher, service_thread, settled_status, wait_offered


def mix_config(**intake: Any) -> ServiceConfig:
    _, cfg = scenario_config("mix")
    return msgspec.structs.replace(cfg, intake=IntakeConfig(**intake))


def stalled(cfg: ServiceConfig, tmp: Path) -> Any:
    """The service with its loop not started until start() (see service_thread)."""
    return service_thread(cfg, started=False, recording_path=tmp / "live.rrd", stream_path=tmp / "live.fstream")


def cam(seq: int, t_ns: int, x: float = 100.0) -> bytes:
    return m.encode(m.Measurement(sensor_id="cam1", t_ns=t_ns, seq=seq,
                                  data=m.Cartesian(pos_m=[x, 50.0], std_m=[3.0, 3.0])))


def radar(seq: int, t_ns: int) -> bytes:
    return m.encode(m.Measurement(sensor_id="radar1", t_ns=t_ns, seq=seq,
                                  data=m.Radar(range_m=2000.0, bearing_rad=1.0, range_std_m=5.0,
                                               bearing_std_rad=0.003)))


def adds_up(c: m.Counts) -> bool:
    return c.received == c.applied + c.inputs + c.truth + c.duplicates + sum(c.refused.values()) + c.queued


def test_byte_limit_and_bounds_cover_every_key(tmp_path: Path) -> None:
    """Truth and wildcard floods are bounded like measurements (they queued 15 107 and 3 242 deep
    against queue_max 50 before); a 1 MB payload is refused before it is copied or decoded."""
    cfg = mix_config(queue_max=50, max_message_bytes=4096)
    ns = cfg.namespace
    truth = m.encode(m.Truth(target_id="x", t_ns=1, state=[0.0, 0.0, 0.0, 0.0], layout=["x", "vx", "y", "vy"]))
    with stalled(cfg, tmp_path) as (svc, endpoint, start):
        s = client(endpoint)
        try:
            big = publisher(s, m.meas_key(ns, "cam1"))
            big.put(b"\x00" * 1_000_000)
            publisher(s, m.truth_key(ns, "x")).put(b"\x00" * 10_000)
            tp = publisher(s, m.truth_key(ns, "x"))
            for _ in range(1000):
                tp.put(truth)
            wild = publisher(s, f"fusion/{ns}/meas/*")
            for i in range(300):
                wild.put(cam(i, 10**9))
            wait_offered(svc, 1302)
            assert svc.intake.max_depth == 50
            assert svc.intake.max_bytes < 50 * 1000
            start()
            status = settled_status(svc, s, ns)
        finally:
            s.close()
    c = status.counts
    assert c.received == 1302 and adds_up(c) and c.queued == 0
    assert c.refused["too_large"] == 2
    assert c.refused["overload"] == 1300 - 50
    # what was queued was handled, half each (fair shares): truth recorded, wildcard puts refused
    assert c.truth == 25 and c.refused["key_mismatch"] == 25
    # the truth refused at the queue (1 too large, 975 over its share) is said as truth, not as measurements
    assert c.truth_refused == 976 and c.inputs_refused == 0
    assert counts_line(msgspec.to_builtins(c)).startswith("received 301 measurements: 0 applied, 0 duplicates dropped, "
                                                          "1277 refused")


def test_a_queue_bounded_in_bytes(tmp_path: Path) -> None:
    cfg = mix_config(queue_max=10_000, queue_max_bytes=200_000, max_message_bytes=60_000)
    ns = cfg.namespace
    with stalled(cfg, tmp_path) as (svc, endpoint, start):
        s = client(endpoint)
        try:
            p = publisher(s, m.meas_key(ns, "radar1"))
            for _ in range(100):
                p.put(b"\x01" * 50_000)  # refused, but only the decoder can tell
            wait_offered(svc, 100)
            assert len(svc.intake) == 3 and svc.intake.max_bytes <= 200_000
            start()
            status = settled_status(svc, s, ns)
        finally:
            s.close()
    c = status.counts
    assert adds_up(c) and c.refused == {"overload": 97, "invalid": 3}


def test_a_flood_from_one_sensor_costs_only_that_sensor(tmp_path: Path) -> None:
    """radar1 floods a queue of 100 behind a stalled tracker; cam1's 20 later samples all keep
    their place (radar1's oldest make room) and are all applied."""
    cfg = mix_config(queue_max=100)
    ns = cfg.namespace
    t0 = time.time_ns()
    with stalled(cfg, tmp_path) as (svc, endpoint, start):
        s = client(endpoint)
        try:
            rp = publisher(s, m.meas_key(ns, "radar1"))
            for i in range(5000):
                rp.put(radar(i, t0 + i * 1000))
            cp = publisher(s, m.meas_key(ns, "cam1"))
            for i in range(20):
                cp.put(cam(i, t0 + i * 100_000_000))
            wait_offered(svc, 5020)
            assert svc.intake.depth_by_source() == {"meas/cam1": 20, "meas/radar1": 80}
            start()
            status = settled_status(svc, s, ns)
        finally:
            s.close()
    c = status.counts
    assert adds_up(c) and c.refused["overload"] == 4920
    assert status.latency["cam1"].count == 20, "a cam1 sample was lost behind radar1's flood"
    assert c.applied == 100


def test_a_live_flood_is_rate_limited_and_the_others_stay_fresh(tmp_path: Path) -> None:
    """While radar1 floods as fast as it can, cam1 at 20 Hz is applied in full and its track's
    estimates keep coming; radar1 beyond its rate is refused "rate_limited"."""
    cfg = mix_config(queue_max=500, source_rate_hz=200.0, source_burst=50)
    ns = cfg.namespace
    stop = threading.Event()
    flooded = [0]
    with stalled(cfg, tmp_path) as (svc, endpoint, start):
        start()
        s, sub = client(endpoint), client(endpoint)
        try:
            col = EstimateCollector(sub, ns)

            def flood() -> None:
                rp = publisher(s, m.meas_key(ns, "radar1"))
                while not stop.is_set():
                    rp.put(radar(flooded[0], time.time_ns()))
                    flooded[0] += 1

            ft = threading.Thread(target=flood)
            ft.start()
            try:
                cp = publisher(s, m.meas_key(ns, "cam1"))
                gaps = []
                last_seen = time.monotonic()
                for i in range(40):
                    cp.put(cam(i, time.time_ns(), x=100.0 + i))
                    time.sleep(0.05)
                    if any(e.sensor_id == "cam1" for e in col.snapshot()[-50:]):
                        gaps.append(time.monotonic() - last_seen)
                        last_seen = time.monotonic()
            finally:
                stop.set()
                ft.join()
            status = settled_status(svc, s, ns)
            got = col.all_of(svc)  # the flood's estimates can still be on their way to the collector
        finally:
            sub.close()
            s.close()
    c = status.counts
    assert adds_up(c)
    assert status.latency["cam1"].count == 40
    assert c.refused["rate_limited"] > 0 and flooded[0] > 1000
    cam_seqs = {e.seq for e in got if e.sensor_id == "cam1"}
    assert max(cam_seqs) == 39, "cam1's last measurement produced no estimate"
    assert len(cam_seqs) >= 35
