"""Tracking quality: fusion's Tracker and Stone Soup's GNN tracker (bench/stonesoup_gnn.py,
configured from the same TrackerConfig) scored with one GOSPA (fusion.core.metrics.gospa_parts:
alpha = 2, p = 2, c = C_M) on identical seeded data, and their time per scan in the same run.

Data (tests/tracking/streams.py): 10 constant-velocity targets (8-15 m/s, random headings,
starting uniform in [-300, 300] m^2) for DURATION_S (40 s: they stay inside the clutter's
square), one sensor scanning every 0.5 s with Pd 0.9 and Poisson clutter (light: 5, heavy: 20
per scan) uniform in [-1, 1] km^2; the sensor is Cartesian (std 5 m per axis) or a radar at
(0, -2.5 km) (5 m, 2 mrad: 5 m across at 2.5 km). Each seed draws truth and
detections once; both trackers get the same scans in time order.
Scored at every scan: the confirmed tracks' positions at the scan time (fusion: Tracker.predict;
Stone Soup: its tracks' last state, a prediction where it missed) against the truth. The
timings cover the trackers' steps only (the scoring and the Stone Soup detection objects are
built outside).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass

import numpy as np

from bench.stonesoup_gnn import StoneSoupGNN
from fusion.config import LifecycleConfig, MotionConfig, TrackerConfig
from fusion.core.metrics import GospaParts, gospa_parts
from fusion.tracking.tracker import Tracker
from tests.tracking.streams import Labeled, Sensor, Truth, constant_velocity, detect, in_order, scans

C_M = 20.0  # GOSPA cut-off (m)
P = 2.0
DURATION_S = 40.0
REGION_M = (-1000.0, 1000.0, -1000.0, 1000.0)
SPREAD_M = 300.0
SENSORS = {
    "cartesian": Sensor("cart", "cartesian", period_s=0.5, std_m=5.0),
    "radar": Sensor("radar", "radar", period_s=0.5, range_std_m=5.0, bearing_std_rad=0.002,
                    position_m=(0.0, -2500.0)),
}
CLUTTER = {"light": 5.0, "heavy": 20.0}


def config(sensor: Sensor) -> TrackerConfig:
    """The configuration both trackers run: CV with q = 0.25 m^2/s^3, gate 0.999, confirmation
    3 of 5, deletion after more than 5 misses (coast_s 3 s = 6 scans agrees)."""
    return TrackerConfig(sensors=[sensor.config()], motion=MotionConfig(accel_psd_m2s3=0.25),
                         lifecycle=LifecycleConfig(confirm_m=3, confirm_n=5, max_misses=5, coast_s=3.0))


def data(sensor: Sensor, clutter: float, seed: int, duration_s: float = DURATION_S
         ) -> tuple[Truth, list[list[Labeled]]]:
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=10, duration_s=duration_s, rng=rng, spread_m=SPREAD_M)
    dets = detect(truth, sensor, rng=rng, pd=0.9, clutter_mean=clutter, region_m=REGION_M)
    return truth, list(scans(in_order(dets)))


@dataclass(frozen=True)
class Run:
    """One tracker on one seed: GOSPA parts per scan and seconds per scan."""

    parts: list[GospaParts]
    step_s: list[float]

    def mean(self, field: str) -> float:
        return statistics.fmean(getattr(g, field) for g in self.parts)


def run_fusion(cfg: TrackerConfig, truth: Truth, data: list[list[Labeled]]) -> Run:
    tr = Tracker(cfg)
    parts, times = [], []
    for scan in data:
        dets = [lab.det for lab in scan]
        t = dets[0].t_ns
        a = time.perf_counter()
        tr.process(dets)
        times.append(time.perf_counter() - a)
        est = np.array([[e.x[0], e.x[2]] for e in tr.predict(t)]).reshape(-1, 2)
        parts.append(gospa_parts(truth.positions(t), est, c=C_M, p=P))
    return Run(parts, times)


def run_stonesoup(cfg: TrackerConfig, truth: Truth, data: list[list[Labeled]]) -> Run:
    ss = StoneSoupGNN(cfg)
    parts, times = [], []
    for scan in data:
        t = scan[0].det.t_ns
        feed = ss.detections(t, np.array([lab.det.z for lab in scan]))
        a = time.perf_counter()
        ss.step(feed)
        times.append(time.perf_counter() - a)
        parts.append(gospa_parts(truth.positions(t), ss.positions(), c=C_M, p=P))
    return Run(parts, times)


def compare(kind: str, clutter: str, seed: int, duration_s: float = DURATION_S) -> tuple[Run, Run]:
    """(fusion, Stone Soup) on one seed of one setting."""
    sensor = SENSORS[kind]
    cfg = config(sensor)
    truth, d = data(sensor, CLUTTER[clutter], seed, duration_s)
    return run_fusion(cfg, truth, d), run_stonesoup(cfg, truth, d)


def _spread(xs: list[float]) -> str:
    return f"{statistics.fmean(xs):.3f} [{min(xs):.3f}, {max(xs):.3f}]"


HEADER = (f"{'setting':>16} {'tracker':>9} {'GOSPA m':>22} {'loc':>6} {'missed':>7} {'false':>6} "
          f"{'n_miss':>6} {'n_false':>7} {'ms/scan':>8}")


def setting(kind: str, clutter: str, seeds: range, duration_s: float) -> dict[str, float]:
    """Both trackers on every seed of one setting: prints its rows, returns its figures."""
    runs = [compare(kind, clutter, s, duration_s) for s in seeds]
    name = f"{kind}/{clutter}"
    res: dict[str, float] = {}
    for label, k in (("fusion", 0), ("stonesoup", 1)):
        rs = [r[k] for r in runs]
        d = [r.mean("distance") for r in rs]
        ms = statistics.median(x for r in rs for x in r.step_s) * 1e3
        parts = [statistics.fmean(r.mean(f) for r in rs) for f in ("localisation", "missed", "false", "n_missed",
                                                                    "n_false")]
        print(f"{name:>16} {label:>9} {_spread(d):>22} " + " ".join(f"{x:6.2f}" for x in parts[:3])
              + f" {parts[3]:6.2f} {parts[4]:7.2f} {ms:8.2f}")
        res[f"{name}/{label}/gospa_m"] = statistics.fmean(d)
        for f, x in zip(("localisation", "missed", "false", "n_missed", "n_false"), parts, strict=True):
            res[f"{name}/{label}/{f}"] = x
        res[f"{name}/{label}/ms_per_scan"] = ms
    diff = [f.mean("distance") - s.mean("distance") for f, s in runs]
    ratio = [statistics.median(s.step_s) / statistics.median(f.step_s) for f, s in runs]
    wins = sum(x <= 1e-9 for x in diff)  # equal runs differ by rounding only
    print(f"{name:>16} fusion - stonesoup GOSPA {_spread(diff)} m, fusion <= stonesoup in {wins}/{len(runs)}; "
          f"speed ratio {statistics.median(ratio):.1f}x [{min(ratio):.1f}, {max(ratio):.1f}]")
    res[f"{name}/gospa_diff_m"] = statistics.fmean(diff)
    res[f"{name}/fusion_at_or_below"] = wins
    res[f"{name}/speed_ratio"] = statistics.median(ratio)
    return res


def run(*, quick: bool = False) -> dict[str, float]:
    seeds = range(3) if quick else range(10)
    duration = 20.0 if quick else DURATION_S
    print(f"GOSPA (alpha 2, p {P:g}, c {C_M:g} m) per scan, mean over {duration:g} s and {len(seeds)} seeds "
          "[min, max over seeds]; parts in m^2 per scan; ms per scan (median) and the ratio per seed")
    print(HEADER)
    res: dict[str, float] = {}
    for kind in SENSORS:
        for clutter in CLUTTER:
            res.update(setting(kind, clutter, seeds, duration))
    return res


if __name__ == "__main__":
    run()
