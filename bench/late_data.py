"""What late data costs, with the tracker the shipped configuration builds (configs/service.toml:
IMM cv+ct, radar1 + cam1, the 2 s window), against the in-order baseline of the same run.

Scenario: the mix's sensors (configs/scenarios/mix.toml: radar1 at 10 Hz, cam1 at 5 Hz, their
Pd and clutter; no latency, drop-outs or duplicates: this benchmark decides what is late) over T
targets of publishers.truth.mix_truth. Figures:
  in order:   every scan delivered in (t_ns, sensor) order, one `process` call per scan; the
              cost per measurement (the first WARM scans, initiation, not timed);
  10 % late:  the same measurements, each one with probability 0.1 held back and delivered with
              a later scan, 1 to 25 scans later (inside the window); throughput against in order;
  k back:     after the stream in order but one measurement, that measurement alone, landing
              k scans before the newest: its cost against the median in-order scan;
  (both also with selective_replay=False, the whole replay of before, as a second reference)
  memory:     bytes per live track held by the tracker (tracemalloc, after the stream) with the
              2 s window against lag_s = 0 (no replay window).
Every detection is stamped with an arrival time, 1 ms after the time of the scan it is delivered
with (`delivered`), as the service's decoding stamps it: the intake then runs the service's path.
Each figure is repeated; medians with min-max spreads are printed. Times are CPU seconds of this
process (time.process_time; BLAS pinned to one thread by bench.__main__), which the other
processes of a shared machine move far less than wall time. The collector is settled as `fusion
serve` settles it (fusion.io.gc_tuning).
"""

from __future__ import annotations

import gc
import statistics
import time
import tracemalloc
from pathlib import Path

import msgspec
import numpy as np

from fusion.config import TrackerConfig, load_service_config
from fusion.io.gc_tuning import settle_garbage_collector
from fusion.io.wire import detection_of
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker
from publishers.sensors import simulate_sensor
from publishers.spec import LatencySpec, load_scenario_file, scenario_path
from publishers.truth import mix_truth

ROOT = Path(__file__).resolve().parent.parent
WARM = 15  # scans of initiation, not timed
ARRIVAL_NS = 1_000_000  # each detection arrives 1 ms after the time of the scan it is delivered with


def delivered(batch: list[Detection], at_ns: int) -> list[Detection]:
    """A batch as the service hands it to the tracker: every detection stamped with its arrival
    time (fusion.pipeline decodes each sample with it), so that the intake runs the path of the
    service (its clocks and window in one compiled pass, fusion.tracking.window_kernel; without
    arrival times they go one detection at a time, a path only direct callers of Tracker take)."""
    return [d._replace(arrival_ns=at_ns) for d in batch]


def arrived(data: list[list[Detection]]) -> list[list[Detection]]:
    """Every scan delivered on time: ARRIVAL_NS after its time."""
    return [delivered(s, s[0].t_ns + ARRIVAL_NS) for s in data]


def shipped_config() -> TrackerConfig:
    """The tracker configuration of configs/service.toml, as fusion.service builds its tracker."""
    return load_service_config(ROOT / "configs" / "service.toml").tracker


def scans(n_targets: int, duration_s: float, *, seed: int = 0) -> list[list[Detection]]:
    """The mix's sensors over n_targets, as scans in (t_ns, sensor) order."""
    spec = load_scenario_file(scenario_path("mix")).scenario
    truths = mix_truth(n_targets=n_targets, dt_s=spec.dt_s, duration_s=duration_s, seed=seed)
    rng = np.random.default_rng(seed)
    by_key: dict[tuple[int, str], list[Detection]] = {}
    for s in spec.sensors:
        quiet = msgspec.structs.replace(s, latency=LatencySpec(), dropout=0.0, duplicate=0.0)
        for e in simulate_sensor(quiet, truths, rng):
            d = detection_of(e.msg)
            by_key.setdefault((d.t_ns, d.sensor_id), []).append(d)
    return [by_key[k] for k in sorted(by_key)]


def _timed(tr: Tracker, calls: list[list[Detection]]) -> list[float]:
    """One process call per batch; the CPU seconds of each call after the first WARM."""
    out = []
    for k, batch in enumerate(calls):
        t0 = time.process_time()
        tr.process(batch)
        if k >= WARM:
            out.append(time.process_time() - t0)
    return out


def in_order(data: list[list[Detection]], cfg: TrackerConfig) -> tuple[Tracker, list[float]]:
    """One process call per scan; the CPU seconds of each call after WARM."""
    tr = Tracker(cfg)
    return tr, _timed(tr, arrived(data))


def with_late(data: list[list[Detection]], cfg: TrackerConfig, *, fraction: float = 0.1, max_back: int = 25,
              seed: int = 1, selective: bool = True) -> tuple[Tracker, list[float], int]:
    """Each measurement held back with probability `fraction`, delivered 1..max_back scans later."""
    rng = np.random.default_rng(seed)
    due: dict[int, list[Detection]] = {}
    calls: list[list[Detection]] = []
    for k, scan in enumerate(data):
        now = []
        for d in scan:
            if k >= WARM and rng.random() < fraction:
                due.setdefault(k + int(rng.integers(1, max_back + 1)), []).append(d)
            else:
                now.append(d)
        calls.append(now + due.pop(k, []))
    calls[-1].extend(d for k in sorted(due) for d in due[k])
    calls = [delivered(c, scan[0].t_ns + ARRIVAL_NS) for c, scan in zip(calls, data, strict=True)]
    tr = Tracker(cfg, selective_replay=selective)
    out = _timed(tr, calls)
    return tr, out, tr.counts.late_applied


def one_late(data: list[list[Detection]], cfg: TrackerConfig, back: int, pick: int, *, selective: bool = True
             ) -> float:
    """CPU seconds of processing measurement `pick` of the scan `back` scans before the newest,
    after all the others."""
    k_late = len(data) - 1 - back
    scan = data[k_late]
    held = scan[pick % len(scan)]
    tr = Tracker(cfg, selective_replay=selective)
    for k, s in enumerate(arrived(data)):
        tr.process([d for d in s if d.seq != held.seq or d.sensor_id != held.sensor_id] if k == k_late else s)
    late = delivered([held], data[-1][0].t_ns + ARRIVAL_NS)
    gc.collect()
    t0 = time.process_time()
    tr.process(late)
    return time.process_time() - t0


def bytes_per_track(data: list[list[Detection]], cfg: TrackerConfig) -> tuple[float, int]:
    """(bytes the tracker holds per live track after the stream, live tracks), by tracemalloc."""
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    tr = Tracker(cfg)
    for s in arrived(data):
        tr.process(s)
    gc.collect()
    held = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    n = len(tr.tracks)
    return held / max(n, 1), n


def _spread(xs: list[float], scale: float = 1.0) -> str:
    return f"{statistics.median(xs) * scale:.2f} [{min(xs) * scale:.2f}-{max(xs) * scale:.2f}]"


def run(*, quick: bool = False) -> dict[str, float]:
    settle_garbage_collector()  # as fusion serve does after start-up
    cfg = shipped_config()
    targets = 100
    duration_s = 6.0 if quick else 10.0
    repeats = 2 if quick else 3
    data = scans(targets, duration_s)
    n_timed = sum(len(s) for s in data[WARM:])
    print(f"late data: configs/service.toml tracker (IMM cv+ct, radar1 10 Hz + cam1 5 Hz, lag 2 s), {targets} "
          f"targets, {len(data)} scans, {n_timed} measurements timed; median [min-max] over {repeats} repeats")
    res: dict[str, float] = {}
    base_rate, scan_ms = [], []
    late_rate: dict[bool, list[float]] = {True: [], False: []}
    ratios: dict[bool, list[float]] = {True: [], False: []}
    for _ in range(repeats):  # interleaved: in order, 10 % late selective, 10 % late whole, in each repeat
        _, t = in_order(data, cfg)
        base_rate.append(n_timed / sum(t))
        scan_ms.append(statistics.median(t) * 1e3)
        for sel in (True, False):
            _, t2, n_late = with_late(data, cfg, selective=sel)
            late_rate[sel].append(n_timed / sum(t2))
            ratios[sel].append(base_rate[-1] / late_rate[sel][-1])
    print(f"  in order:      {_spread(base_rate, 1e-3)} k measurements/s (CPU), median scan {_spread(scan_ms)} ms")
    for sel, name in ((True, "selective replay"), (False, "whole replay (before)")):
        print(f"  10 % late, {name} ({n_late} applied late, 1-25 scans back): {_spread(late_rate[sel], 1e-3)} k "
              f"measurements/s; in-order/late {_spread(ratios[sel])}x (goal <= 2x)")
    res.update(in_order_kps=statistics.median(base_rate) * 1e-3, late10_kps=statistics.median(late_rate[True]) * 1e-3,
               late10_ratio=statistics.median(ratios[True]), late10_whole_ratio=statistics.median(ratios[False]),
               scan_ms=statistics.median(scan_ms))
    backs = (0, 1, 5) if quick else (0, 1, 5, 20)
    scan_med = statistics.median(scan_ms)
    for back in backs:
        c, w = [], []
        for pick in range(repeats + 2):
            c.append(one_late(data, cfg, back, pick) * 1e3)
            w.append(one_late(data, cfg, back, pick, selective=False) * 1e3)
        rel, wrel = [x / scan_med for x in c], [x / scan_med for x in w]
        print(f"  {back:3d} scans back: {_spread(c)} ms, {_spread(rel)}x one in-order scan (goal at 20: <= 5x); "
              f"whole replay {_spread(w)} ms, {_spread(wrel)}x")
        res[f"back_{back}_ms"] = statistics.median(c)
        res[f"back_{back}_ratio"] = statistics.median(rel)
        res[f"back_{back}_whole_ratio"] = statistics.median(wrel)
    mem_w, n_w = bytes_per_track(data, cfg)
    no_window = msgspec.structs.replace(cfg, time=msgspec.structs.replace(cfg.time, lag_s=0.0))
    mem_0, n_0 = bytes_per_track(data, no_window)
    print(f"  memory: {mem_w / 1e3:.1f} kB per track with the 2 s window ({n_w} tracks), {mem_0 / 1e3:.1f} kB "
          f"without ({n_0} tracks): {mem_w / mem_0:.2f}x (goal <= 2x)")
    res.update(kb_per_track_window=mem_w / 1e3, kb_per_track_none=mem_0 / 1e3, memory_ratio=mem_w / mem_0)
    return res


if __name__ == "__main__":
    run()
