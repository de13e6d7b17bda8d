"""Tracker cost per scan at 10, 100 and 1000 targets with clutter, against Stone Soup's GNN
tracker on the same scans in the same process; and the cost of a late measurement as a function
of how far back it lands.

Scenario: T constant-velocity targets in a 10 km square, one Cartesian sensor (std 1 m) at
10 Hz, Pd = 1, Poisson clutter with mean T/10 per scan. Both trackers get the same scans; the
first 5 scans (initiation) are not timed.
"""

from __future__ import annotations

import statistics
import time

import msgspec
import numpy as np

from bench.stonesoup_gnn import StoneSoupGNN
from fusion.config import CartesianSensorConfig, LifecycleConfig, MotionConfig, TimeConfig, TrackerConfig
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker

DT_S = 0.1


def scans(n_targets: int, n_scans: int, *, seed: int = 0) -> list[list[tuple[float, float]]]:
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-5000, 5000, n_targets), rng.uniform(-20, 20, n_targets),
                         rng.uniform(-5000, 5000, n_targets), rng.uniform(-20, 20, n_targets)])
    out = []
    for _ in range(n_scans):
        x[:, 0] += x[:, 1] * DT_S
        x[:, 2] += x[:, 3] * DT_S
        pts = x[:, [0, 2]] + rng.normal(0, 1.0, (n_targets, 2))
        clutter = rng.uniform(-5000, 5000, (rng.poisson(n_targets / 10), 2))
        out.append([tuple(p) for p in np.vstack([pts, clutter])])
    return out


def config(**lifecycle: int) -> TrackerConfig:
    """The configuration both trackers run (Stone Soup's through bench.stonesoup_gnn)."""
    return TrackerConfig(sensors=[CartesianSensorConfig(id="cam", std_m=[1.0, 1.0])],
                         motion=MotionConfig(accel_psd_m2s3=0.25), lifecycle=LifecycleConfig(**lifecycle))


def fusion_per_scan(data: list, *, warm: int = 5) -> list[float]:
    tr = Tracker(config(max_tracks=1_000_000))
    seq = 0
    out = []
    for k, scan in enumerate(data):
        t = round((k + 1) * DT_S * 1e9)
        dets = []
        for p in scan:
            dets.append(Detection.of("cam", t, seq, p))
            seq += 1
        t0 = time.perf_counter()
        tr.process(dets)
        if k >= warm:
            out.append(time.perf_counter() - t0)
    return out


def stonesoup_per_scan(data: list, *, warm: int = 5) -> list[float]:
    """Stone Soup's step per scan, the building of its detection objects included (fusion's
    Detection objects are built outside its timing: they are what its intake receives)."""
    ss = StoneSoupGNN(config())
    times: list[float] = []
    for k, scan in enumerate(data):
        a = time.perf_counter()
        ss.step(ss.detections(round((k + 1) * DT_S * 1e9), np.array(scan)))
        if k >= warm:
            times.append(time.perf_counter() - a)
    return times


def late_cost(n_targets: int = 100, n_scans: int = 40, backs: tuple[int, ...] = (0, 1, 5, 10, 20)) -> dict[int, float]:
    """Cost of one measurement that lands `back` scans before the newest (replaying them)."""
    data = scans(n_targets, n_scans, seed=1)
    cfg = msgspec.structs.replace(config(), time=TimeConfig(lag_s=10.0))
    out = {}
    for back in backs:
        costs = []
        for rep in range(5):
            tr = Tracker(cfg)
            seq = 0
            held = None
            for k, scan in enumerate(data):
                t = round((k + 1) * DT_S * 1e9)
                dets = []
                for j, p in enumerate(scan):
                    d = Detection.of("cam", t, seq, p)
                    seq += 1
                    if k == n_scans - 1 - back and j == rep:
                        held = d  # withheld: it arrives after the last scan
                    else:
                        dets.append(d)
                tr.process(dets)
            a = time.perf_counter()
            tr.process([held])  # type: ignore[list-item]
            costs.append(time.perf_counter() - a)
        out[back] = statistics.median(costs)
    return out


def run(*, quick: bool = False) -> dict[str, float]:
    sizes = (10, 100) if quick else (10, 100, 1000)
    n_scans = 15 if quick else 25
    res: dict[str, float] = {}
    print(f"tracker cost per scan (median over {n_scans - 5} scans after 5 to start; clutter T/10 per scan)")
    print(f"{'targets':>8} {'fusion ms':>10} {'us/meas':>8} {'stonesoup ms':>13} {'ratio':>7}")
    for T in sizes:
        data = scans(T, n_scans)
        n_meas = statistics.mean(len(s) for s in data)
        f = statistics.median(fusion_per_scan(data))
        s = None
        if T <= 100 or not quick:
            ss_data = data if T <= 100 else data[:8]  # Stone Soup at 1000 targets: a few scans only
            s = statistics.median(stonesoup_per_scan(ss_data, warm=5 if T <= 100 else 6))
        res[f"fusion_ms_{T}"] = f * 1e3
        if s is not None:
            res[f"stonesoup_ms_{T}"] = s * 1e3
        print(f"{T:8d} {f * 1e3:10.2f} {f / n_meas * 1e6:8.1f} {'-' if s is None else f'{s * 1e3:13.1f}':>13} "
              f"{'-' if s is None else f'{s / f:6.1f}x':>7}")
    lc = late_cost(backs=(0, 1, 5) if quick else (0, 1, 5, 10, 20))
    print("late measurement at 100 targets: cost by how many scans back it lands (replays that many scans)")
    for back, c in lc.items():
        print(f"  {back:3d} scans back: {c * 1e3:8.2f} ms")
        res[f"late_ms_back_{back}"] = c * 1e3
    return res


if __name__ == "__main__":
    run()
