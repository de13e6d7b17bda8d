"""Interleaved A/B of where the recording is written: on its own thread (`[recording] background =
true`, shipped) against on the service's loop (`background = false`), both the real `fusion serve`
of bench.service_e2e with recording on, a fresh service for every run, alternating A, B, A, B...

Per pair: publish-to-estimate latency at 10k measurements/s offered (667 targets) and at 1k/s (67
targets) over `duration_s` (20 s by default: a view flush, every 15 s, falls inside), and the
blast throughput at 1000 targets (bench.service_e2e.throughput_run). Printed: each pair, then the
median and range of each figure per variant and the ratio thread/loop per pair.

    python -m bench --only recording_ab [--pairs 3]
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

from bench.ab_table import print_ab
from bench.e2e_procs import Publisher
from bench.service_e2e import latency_run, throughput_run

VARIANTS = {"thread": {}, "loop": {"background": False}}  # [recording] keys over configs/service.toml


def run(*, pairs: int = 3, duration_s: float = 20.0, quick: bool = False) -> dict[str, Any]:
    if quick:
        pairs, duration_s = 1, 6.0
    rows: list[dict[str, Any]] = []
    print(f"recording A/B: thread (shipped) against loop, {pairs} interleaved pairs, recording on; load average "
          f"{os.getloadavg()}", flush=True)
    with tempfile.TemporaryDirectory(prefix="fusion-rec-ab-") as d, Publisher() as pub:
        tmp = Path(d)
        n = 150_000
        pub.call("prepare", {"targets": 1000, "messages": n, "seed": 1000}, timeout_s=300.0)
        for k in range(pairs):
            order = list(VARIANTS) if k % 2 == 0 else list(reversed(VARIANTS))
            for name in order:
                keys = VARIANTS[name]
                row: dict[str, Any] = {"variant": name, "pair": k}
                for rate in (10_000, 1_000):
                    r = latency_run(pub, tmp / f"lat-{rate}-{name}-{k}", rate=rate, recording=True,
                                    duration_s=duration_s, grace_s=3.0, recording_keys=keys)
                    row[f"lat{rate}"] = r
                t = throughput_run(pub, tmp / f"tp-{name}-{k}", n=n, targets=1000, recording=True, window_s=5.0,
                                   warm_deadline_s=60.0, after_warm_s=40.0, recording_keys=keys)
                row["throughput"] = t
                rows.append(row)
                print(f"  pair {k} {name:6s}: 10k/s p50 {_ms(row['lat10000']['p50_ms'])} p99 "
                      f"{_ms(row['lat10000']['p99_ms'])} max {_ms(row['lat10000']['max_ms'])} kept up "
                      f"{row['lat10000']['kept_up']}; 1k/s p50 {_ms(row['lat1000']['p50_ms'])} p99 "
                      f"{_ms(row['lat1000']['p99_ms'])} max {_ms(row['lat1000']['max_ms'])}; blast at 1000 targets "
                      f"{(t['rate'] or 0):,.0f}/s", flush=True)
    print_ab(rows, new="thread", old="loop", new_header="thread (shipped)", old_header="loop")
    return {"rows": rows, "loadavg_end": os.getloadavg()}


def _ms(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1f} ms"
