"""A flood from one sensor against the real service, from a real zenoh client, with figures.

    python tools/flood_probe.py --seconds 20 --rate-hz 200

radar1 publishes as fast as one client can (CongestionControl.BLOCK) while cam1 publishes at
20 Hz; the service runs the mix configuration with queue_max 500 and, unless --rate-hz 0, a
per-source rate limit. Printed: messages sent per sensor, the service's counts by reason (they
add up), the deepest the queue got, cam1's samples applied, the longest wait between two of
cam1's estimates, and the process's RSS before and after.
"""

from __future__ import annotations

import argparse
import itertools
import resource
import sys
import tempfile
import threading
import time
from pathlib import Path

import msgspec

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion import messages as m
from fusion.config import IntakeConfig, ZenohConfig
from fusion.io.zenoh_bus import free_tcp_port
from fusion.service import Service
from tests.service.harness import client, query, scenario_config


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main(seconds: float, rate_hz: float) -> int:
    import zenoh

    _, cfg = scenario_config("mix")
    cfg = msgspec.structs.replace(cfg, intake=IntakeConfig(queue_max=500, source_rate_hz=rate_hz, source_burst=50))
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    tmp = Path(tempfile.mkdtemp())
    svc = Service(msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="peer", listen=[ep])),
                  recording_path=tmp / "probe.rrd", stream_path=tmp / "probe.fstream")
    svc.open()
    t = threading.Thread(target=svc.run)
    t.start()
    rss0 = rss_mb()
    s, sub = client(ep), client(ep)
    cam_times: list[float] = []
    sub.declare_subscriber(m.all_tracks_key(cfg.namespace), lambda smp: cam_times.append(time.monotonic())
                           if m.decode_estimate(smp.payload.to_bytes()).sensor_id == "cam1" else None)
    stop = threading.Event()
    sent = {"radar1": 0, "cam1": 0}
    BLOCK = zenoh.CongestionControl.BLOCK

    def flood() -> None:
        p = s.declare_publisher(m.meas_key(cfg.namespace, "radar1"), congestion_control=BLOCK)
        while not stop.is_set():
            p.put(m.encode(m.Measurement(sensor_id="radar1", t_ns=time.time_ns(), seq=sent["radar1"], data=m.Radar(
                range_m=2000.0, bearing_rad=1.0, range_std_m=5.0, bearing_std_rad=0.003))))
            sent["radar1"] += 1

    ft = threading.Thread(target=flood)
    time.sleep(0.3)
    ft.start()
    cp = s.declare_publisher(m.meas_key(cfg.namespace, "cam1"), congestion_control=BLOCK)
    end = time.monotonic() + seconds
    i = 0
    while time.monotonic() < end:
        cp.put(m.encode(m.Measurement(sensor_id="cam1", t_ns=time.time_ns(), seq=i,
                                      data=m.Cartesian(pos_m=[100.0 + i * 0.5, 50.0], std_m=[3.0, 3.0]))))
        i += 1
        sent["cam1"] = i
        time.sleep(0.05)
    stop.set()
    ft.join()
    svc.wait_idle(timeout_s=120)
    time.sleep(0.2)
    st = m.decode_status(query(s, m.status_key(cfg.namespace)))
    rss1 = rss_mb()
    sub.close()
    s.close()
    svc.stop()
    t.join()
    c = st.counts
    gaps = [b - a for a, b in itertools.pairwise(cam_times)]
    print(f"flood probe: {seconds:.0f} s, rate limit {rate_hz or 'off'} Hz/source, queue_max 500")
    print(f"  sent: radar1 {sent['radar1']} (flood), cam1 {sent['cam1']} (20 Hz)")
    adds_up = c.received == c.applied + c.truth + c.duplicates + sum(c.refused.values()) + c.queued
    print(f"  counts: received {c.received} = applied {c.applied} + duplicates {c.duplicates} + refused "
          f"{sum(c.refused.values())} {dict(c.refused)} + queued {c.queued}: "
          f"{'adds up' if adds_up else 'DOES NOT ADD UP'}")
    print(f"  queue: deepest {svc.intake.max_depth} samples, {svc.intake.max_bytes / 1e6:.2f} MB")
    print(f"  cam1: {st.latency['cam1'].count} of {sent['cam1']} decoded, {len(cam_times)} estimates, longest gap "
          f"between two {max(gaps) if gaps else float('nan'):.3f} s")
    print(f"  RSS {rss0:.0f} MB -> {rss1:.0f} MB")
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate-hz", type=float, default=200.0)
    a = ap.parse_args()
    raise SystemExit(main(a.seconds, a.rate_hz))
