"""A backlog worked off in full batches: the batch's last scan held for the rest (the service's
`Pipeline.ingest(batch, more=True)`) against run and run again (a rescan), in-process, interleaved.

What runs: the shipped configuration's pipeline (configs/service.toml: IMM, radar1 + cam1) on the
end-to-end benchmark's blast (bench.e2e_load.Prepared: T targets, radar1 at 10 Hz and cam1 at 5 Hz
as contiguous bursts, no truth; arrival = sensor time + 1 ms) in batches of intake.batch_max
(5 000), as the service's loop takes them from a full queue; the collector settled as `fusion
serve` settles it. CPU time per measurement over the second half of the stream (the first half:
births and confirmation), median [min-max] over the repeats, and the ratio held/cut per repeat.

    python -m bench.held_scans [--targets 1000] [--repeats 4]
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from bench.e2e_load import SENSORS, Prepared
from bench.recording_cost import CONFIG
from fusion import messages as m
from fusion.config import load_service_config
from fusion.io import wire
from fusion.io.gc_tuning import settle_garbage_collector
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker


def records(targets: int, n: int, ns: str) -> list[tuple[int, str, bytes]]:
    p = Prepared(targets, n, seed=targets)
    p.restamp(1_000_000_000)
    keys = [m.meas_key(ns, s) for s in SENSORS]
    return [(p.t0_ns + rel + 1_000_000, keys[s], bytes(b)) for s, b, rel in zip(p.sensor, p.buf, p.rel_ns, strict=True)]


def one(recs: list, *, held: bool, batch: int) -> tuple[float, int]:
    cfg = load_service_config(CONFIG)
    pipe = Pipeline(Tracker(cfg.tracker), wire.Codec(cfg.namespace))
    half = len(recs) // 2
    t0 = 0.0
    for i in range(0, len(recs), batch):
        if i >= half and not t0:
            t0 = time.process_time()
        pipe.ingest(recs[i:i + batch], more=held and i + batch < len(recs))
    n = len(recs) - (half // batch + (half % batch > 0)) * batch
    return (time.process_time() - t0) / n * 1e6, pipe.tracker.arrival_counts["rescans"]


def run(*, targets: int = 1000, repeats: int = 4, batch: int = 5000) -> dict:
    logging.disable(logging.WARNING)
    ns = load_service_config(CONFIG).namespace
    recs = records(targets, 30 * targets * 15 // 10, ns)  # 3 s of sensor time
    settle_garbage_collector()
    out: dict[str, list] = {"cut": [], "held": [], "rescans": []}
    for k in range(repeats):
        for name in (("cut", "held") if k % 2 == 0 else ("held", "cut")):
            us, rescans = one(recs, held=name == "held", batch=batch)
            out[name].append(us)
            print(f"  {k} {name}: {us:.1f} us per measurement, {rescans} rescans", flush=True)
    ratios = [h / c for h, c in zip(out["held"], out["cut"], strict=True)]
    print(f"{targets} targets, {len(recs)} measurements, batches of {batch}: cut {np.median(out['cut']):.1f} "
          f"[{min(out['cut']):.1f}-{max(out['cut']):.1f}] us, held {np.median(out['held']):.1f} "
          f"[{min(out['held']):.1f}-{max(out['held']):.1f}] us; held/cut per repeat "
          + ", ".join(f"{r:.2f}" for r in ratios))
    return out | {"ratios": ratios}


if __name__ == "__main__":
    a = argparse.ArgumentParser(prog="python -m bench.held_scans")
    a.add_argument("--targets", type=int, default=1000)
    a.add_argument("--repeats", type=int, default=4)
    args = a.parse_args()
    from fusion.io.blas import pin_blas_threads

    pin_blas_threads()
    run(targets=args.targets, repeats=args.repeats)
