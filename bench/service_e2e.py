"""End to end: the service as shipped (`fusion serve --config configs/service.toml`: IMM, radar1
+ cam1, recording on), a real subprocess on 127.0.0.1, fed over Zenoh by a publisher process.

Throughput: N pre-encoded measurements of T targets (bench.e2e_load: the sparse grid scene, and
the dense scene of the mix's sensors with the recording on) blasted with congestion control
BLOCK; the service's status counters (queried every 0.1 s) give measurements applied
per second over a window that starts once 4T are applied (tracks confirmed) and ends when the
backlog is drained or `window_s` later; time to drain = last put -> queued 0. Baseline: the same
messages from the same publisher process to a subscriber process that only counts.
Latency: scans due on the wall clock (t_ns = due time), each sent as one burst, at 1k and 10k
measurements/s offered (67 and 667 targets at 15 messages per target per second); latency =
arrival of an estimate at a subscriber here - its t_ns, the first revision of each estimate,
after a warm-up of 2 s, over 20 s of scans (4 s with --quick): longer than the recording's view
flush interval (15 s), so the view flush's wait is among what is measured. The soak (10k/s
offered for soak_s, the service's resident memory) is bench.soak.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.e2e_load import MSGS_PER_TARGET_S
from bench.e2e_procs import Publisher, ServiceProcess, prime, zenoh_baseline
from fusion import messages as m

SCENES = ("grid", "dense")  # bench.e2e_load: Scene (sparse, the goals' figures), dense_ticks (the mix's sensors)


def _counts_add_up(c: m.Counts) -> bool:
    return c.received == c.applied + c.inputs + c.truth + c.duplicates + sum(c.refused.values()) + c.queued


def throughput_run(pub: Publisher, folder: Path, *, n: int, targets: int, recording: bool, window_s: float,
                   warm_deadline_s: float, after_warm_s: float,
                   recording_keys: dict[str, Any] | None = None) -> dict[str, Any]:
    """One blast of the prepared messages at a fresh service; see the module docstring. The
    service refreshes its status between batches (up to intake.batch_max = 5000 samples), so
    the window runs from the first refresh after 4T were applied (warm-up: births and
    confirmation) to the first refresh at least window_s later, or to the drain, or to the last
    refresh before the deadline (warm_deadline_s from the blast for the warm-up, then
    window_s + after_warm_s). Without a refresh after the warm-up, the window is the whole run
    ("warm": False)."""
    estimates = [0]

    def on_estimate(_t: int, _p: bytes) -> None:
        estimates[0] += 1

    folder.mkdir()
    with ServiceProcess(folder, recording=recording, on_estimate=on_estimate, recording_keys=recording_keys) as svc:
        pub.call("connect", svc.endpoint)
        prime_s, base = prime(svc, pub, timeout_s=120.0)
        t_start = time.monotonic()
        pub.send("blast")
        blast: dict[str, Any] | None = None
        snaps: list[tuple[float, m.ServiceStatus]] = []
        first = drained_wall = None
        bad_counts = 0
        while True:
            if blast is None and pub.conn.poll(0):
                blast = pub.result(0)
            st, now = svc.status(), time.monotonic()
            if st is not None and (not snaps or st.uptime_s != snaps[-1][1].uptime_s):
                snaps.append((now, st))
                bad_counts += not _counts_add_up(st.counts)
                c = st.counts
                if first is None and c.applied >= base.applied + 4 * targets:
                    first = len(snaps) - 1
                if blast is not None and c.received >= base.received + n and c.queued == 0:
                    drained_wall = time.time_ns()
                    break
                if first is not None and len(snaps) - 1 > first and now >= snaps[first][0] + window_s:
                    break
            if first is None and now > t_start + warm_deadline_s:
                break
            if first is not None and now > snaps[first][0] + window_s + after_warm_s:
                break
            time.sleep(0.1)
        if blast is None:
            blast = pub.result(60.0)
        pub.call("disconnect")
        disk = svc.folder_bytes() if recording else {}
    last = snaps[-1][1]
    warm = first is not None and first < len(snaps) - 1
    a = snaps[first][1] if warm else snaps[0][1]  # type: ignore[index]
    span = last.uptime_s - a.uptime_s
    c = last.counts
    out: dict[str, Any] = {
        "targets": targets, "recording": recording, "sent": blast["sent"],
        "send_rate": blast["sent"] / max(blast["t1_ns"] - blast["t0_ns"], 1) * 1e9,
        "rate": (c.applied - a.counts.applied) / span if span > 0 else None,
        "window_s": span, "window_applied": c.applied - a.counts.applied, "warm": warm,
        "drained": drained_wall is not None,
        "drain_s": None if drained_wall is None else (drained_wall - blast["t1_ns"]) / 1e9,
        "total_rate": None if drained_wall is None
        else (c.applied - base.applied) / ((drained_wall - blast["t0_ns"]) / 1e9),
        "prime_s": prime_s, "unhandled_end": base.received + n - (c.received - c.queued),
        "received": c.received, "applied": c.applied,
        "refused": dict(c.refused), "duplicates": c.duplicates, "replays": c.replays, "late_applied": c.late_applied,
        "published": c.published,
        "estimates_seen": estimates[0], "counts_add_up": bad_counts == 0, "status_updates": len(snaps),
        "tracks": dict(last.tracks),
    }
    if recording:
        out["recording_bytes_per_meas"] = last.recording_bytes / max(c.applied, 1)
        out["disk_bytes_per_meas"] = {k: v / max(c.applied, 1) for k, v in disk.items()}
    return out


def latency_run(pub: Publisher, folder: Path, *, rate: int, recording: bool, duration_s: float,
                grace_s: float, warm_s: float = 2.0, seed: int = 7,
                recording_keys: dict[str, Any] | None = None, late: float = 0.0) -> dict[str, Any]:
    got: list[tuple[int, bytes]] = []
    targets = round(rate / MSGS_PER_TARGET_S)
    folder.mkdir()
    with ServiceProcess(folder, recording=recording, on_estimate=lambda t, p: got.append((t, p)),
                        recording_keys=recording_keys) as svc:
        pub.call("connect", svc.endpoint)
        _, base = prime(svc, pub, timeout_s=120.0)
        start_ns = time.time_ns() + 1_000_000_000
        sent = pub.call("paced", {"targets": targets, "seed": seed, "start_ns": start_ns, "duration_s": duration_s,
                                  "late": late},
                        timeout_s=duration_s + 60.0)
        deadline = time.monotonic() + grace_s
        waited_from = sent["t1_ns"]
        st = svc.status()
        while time.monotonic() < deadline and (st is None or st.counts.received < base.received + sent["sent"]
                                               or st.counts.queued):
            time.sleep(0.1)
            st = svc.status() or st
        waited_s = (time.time_ns() - waited_from) / 1e9
        pub.call("disconnect")
    warm_ns = start_ns + round(warm_s * 1e9)
    first: dict[tuple[int, int, str], int] = {}
    for t, p in got:
        e = m.decode_estimate(p)
        k = (e.track_id, e.t_ns, e.sensor_id)
        if e.status != "retracted" and e.t_ns >= warm_ns and k not in first:
            first[k] = t - e.t_ns
    lat = np.array(sorted(first.values()), dtype=np.float64) / 1e6
    offered_after_warm = targets * round((duration_s - warm_s) * MSGS_PER_TARGET_S)
    c = st.counts if st is not None else None
    kept_up = c is not None and c.queued == 0 and c.received >= base.received + sent["sent"]

    def pct(q: float) -> float | None:
        """Over the estimates that arrived; when the service fell behind, the measurements without
        an estimate count as later than any that arrived (None: the percentile is among them)."""
        n_all = len(lat) if kept_up else max(offered_after_warm, len(lat))
        i = min(math.ceil(q / 100 * n_all) - 1, n_all - 1)
        return float(lat[max(i, 0)]) if 0 <= i < len(lat) else None

    return {
        "rate": rate, "targets": targets, "recording": recording, "sent": sent["sent"],
        "publisher_late_p50_ms": sent["late_p50_ms"], "publisher_late_max_ms": sent["late_max_ms"],
        "burst_p50_ms": sent["burst_p50_ms"],
        "estimates": len(lat), "coverage": len(lat) / offered_after_warm,
        "p50_ms": pct(50), "p99_ms": pct(99), "max_ms": pct(100),
        "kept_up": kept_up, "waited_after_publishing_s": waited_s,
        "unhandled_end": None if c is None else base.received + sent["sent"] - (c.received - c.queued),
        "refused": None if c is None else dict(c.refused),
    }


def run(*, quick: bool = False) -> dict[str, Any]:
    from bench.e2e_report import latency_line, print_latency, print_throughput, throughput_line

    repeats = 1 if quick else 3
    n = 60_000 if quick else 150_000
    window_s, warm_dl, after_warm_s = (4.0, 40.0, 30.0) if quick else (5.0, 60.0, 40.0)
    dur, grace = (4.0, 2.0) if quick else (20.0, 3.0)  # 20 s: a view flush (every 15 s) falls in
    out: dict[str, Any] = {"throughput": [], "baseline": [], "latency": [], "loadavg_start": os.getloadavg()}
    print(f"end to end: fusion serve --config configs/service.toml; load average {out['loadavg_start']}", flush=True)
    with tempfile.TemporaryDirectory(prefix="fusion-e2e-") as d, Publisher() as pub:
        tmp = Path(d)
        for targets in (100, 1000):
            for scene in SCENES:  # the dense scene with the recording on only (the shipped configuration)
                prep = pub.call("prepare", {"targets": targets, "messages": n, "seed": targets,
                                            "dense": scene == "dense"}, timeout_s=300.0)
                print(f"T={targets}, {scene} scene: {n} measurements prepared ({prep['bytes'] / n:.0f} bytes each, "
                      f"{prep['sensor_s']:.0f} s of sensor time)", flush=True)
                for rep in range(repeats):
                    base = zenoh_baseline(pub, n) | {"targets": targets, "scene": scene}
                    out["baseline"].append(base)
                    print(f"  zenoh baseline: {base['rate']:,.0f}/s", flush=True)
                    for rec in (True, False) if scene == "grid" else (True,):
                        r = throughput_run(pub, tmp / f"tp-{scene}-{targets}-{rec}-{rep}", n=n, targets=targets,
                                           recording=rec, window_s=window_s, warm_deadline_s=warm_dl,
                                           after_warm_s=after_warm_s) | {"scene": scene}
                        out["throughput"].append(r | {"baseline_rate": base["rate"]})
                        print("  " + throughput_line(r), flush=True)
        for rate in (1_000, 10_000):
            for rep in range(repeats):
                for rec in (True, False):
                    r = latency_run(pub, tmp / f"lat-{rate}-{rec}-{rep}", rate=rate, recording=rec, duration_s=dur,
                                    grace_s=grace)
                    out["latency"].append(r)
                    print("  " + latency_line(r), flush=True)
    out["loadavg_end"] = os.getloadavg()
    print_throughput(out, repeats=repeats, n=n)
    print_latency(out, repeats=repeats, duration_s=dur)
    return out
