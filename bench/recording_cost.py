"""Cost of recording every step to Rerun, per measurement, at 10, 100 and 1000 tracks.

Scenario (bench.tracker_scan.scans): T constant-velocity targets in a 10 km square, one Cartesian
sensor at 10 Hz with clutter (T/10 false returns per scan), the truth of every target logged at
every scan (so estimates are scored: error, NEES, OSPA). Each scan goes through Tracker.process
and the result to the sink with log_step, as fusion.pipeline does. Three runs interleaved per
repeat: no sink (the baseline), the shipped RerunSink, and main's sink before this change (read
from git as a reference only, when the repository has a `main` branch). Reported: microseconds per
measurement; the sink's share two ways: the difference (with sink - without) / measurements,
which the machine's load makes noisy, and the time inside the sink's own calls (log_truth,
log_step and the flushes on the sink's cadence) / measurements; the final flush of what is
pending plus the close, a cost per file, apart in milliseconds.
"""

from __future__ import annotations

import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.tracker_scan import scans
from fusion.config import CartesianSensorConfig, LifecycleConfig, MotionConfig, TrackerConfig
from fusion.io.rerun_sink import RerunSink
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker

REPO = Path(__file__).resolve().parents[1]


def _main_sink() -> Any:
    """main's RerunSink class, loaded from `git show main:fusion/io/rerun_sink.py` (None without it)."""
    try:
        src = subprocess.run(["git", "-C", str(REPO), "show", "main:fusion/io/rerun_sink.py"], capture_output=True,
                             text=True, check=True, timeout=30).stdout
    except (subprocess.SubprocessError, OSError):
        return None
    path = Path(tempfile.mkdtemp()) / "main_rerun_sink.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("main_rerun_sink", path)
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules["main_rerun_sink"] = mod
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod.RerunSink


def _config() -> TrackerConfig:
    return TrackerConfig(sensors=[CartesianSensorConfig(id="cam", std_m=[1.0, 1.0])],
                         motion=MotionConfig(accel_psd_m2s3=0.1), lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3))


def _truths(n_targets: int, n_scans: int, *, seed: int = 0) -> list[np.ndarray]:
    """The true states of bench.tracker_scan.scans (same seed, same draws)."""
    rng = np.random.default_rng(seed)
    x = np.column_stack([rng.uniform(-5000, 5000, n_targets), rng.uniform(-20, 20, n_targets),
                         rng.uniform(-5000, 5000, n_targets), rng.uniform(-20, 20, n_targets)])
    out = []
    for _ in range(n_scans):
        x = x + 0.1 * np.column_stack([x[:, 1], np.zeros(n_targets), x[:, 3], np.zeros(n_targets)])
        out.append(x.copy())
    return out


def _run(data: list, truths: list, kind: str, cls: Any, tmp: Path) -> tuple[float, float, float, int]:
    """(seconds of steady-state processing with the flushes on the sink's cadence, seconds inside
    the sink's calls (log_truth, log_step and the flushes they make), seconds of the final flush
    and close, measurements)."""
    tr = Tracker(_config())
    sink = None
    if cls is not None:
        sink = cls(tmp / f"{kind}.rrd", layout=tr.layout, position_indices=tr.position_indices,
                   velocity_indices=tr.velocity_indices, counts=lambda: tr.counts.flat())
    seq = n_meas = 0
    inside = 0.0
    t0 = time.perf_counter()
    for k, pts in enumerate(data):
        t = (k + 1) * 100_000_000
        if sink is not None:
            a = time.perf_counter()
            for j, x in enumerate(truths[k]):
                sink.log_truth(f"target{j}", t, x)
            inside += time.perf_counter() - a
        dets = []
        for p in pts:
            dets.append(Detection.of("cam", t, seq, p))
            seq += 1
        n_meas += len(dets)
        r = tr.process(dets)
        if sink is not None:
            a = time.perf_counter()
            sink.log_step(r)
            inside += time.perf_counter() - a
    steady = time.perf_counter() - t0
    if sink is not None:
        sink.close()  # the final flush of everything pending, and the footer
    return steady, inside, time.perf_counter() - t0 - steady, n_meas


def run(*, quick: bool = False) -> dict[str, float]:
    sinks: dict[str, Any] = {"none": None, "shipped": RerunSink}
    main = _main_sink()
    if main is not None:
        sinks["main (before)"] = main
    repeats = 2 if quick else 3
    out: dict[str, float] = {}
    print("recording cost per measurement: T CV targets, one sensor at 10 Hz, clutter T/10 per scan, truth logged; "
          f"median [min, max] of {repeats} interleaved repeats")
    print(f"{'tracks':>6} {'sink':>14} {'us/meas':>10} {'difference us/meas':>22} {'in sink us/meas':>22} "
          f"{'x no sink':>9} {'close ms':>9}")
    for n_targets in (10, 100, 1000):
        n_scans = ({10: 100, 100: 40, 1000: 15} if quick else {10: 300, 100: 100, 1000: 40})[n_targets]
        data = scans(n_targets, n_scans)
        truths = _truths(n_targets, n_scans)
        times: dict[str, list[float]] = {k: [] for k in sinks}
        closing: dict[str, list[float]] = {k: [] for k in sinks}
        inside: dict[str, list[float]] = {k: [] for k in sinks}
        n_meas = 0
        with tempfile.TemporaryDirectory() as d:
            for _ in range(repeats):
                for kind, cls in sinks.items():
                    s, i, c, n_meas = _run(data, truths, kind.split()[0], cls, Path(d))
                    times[kind].append(s)
                    inside[kind].append(i)
                    closing[kind].append(c)
        base = statistics.median(times["none"])
        for kind, v in times.items():
            med = statistics.median(v)
            share = [(x - b) / n_meas * 1e6 for x, b in zip(v, times["none"], strict=True)]
            spread = "" if kind == "none" else f"{statistics.median(share):8.1f} [{min(share):.1f}, {max(share):.1f}]"
            ins = [x / n_meas * 1e6 for x in inside[kind]]
            ins_s = "" if kind == "none" else f"{statistics.median(ins):8.1f} [{min(ins):.1f}, {max(ins):.1f}]"
            print(f"{n_targets:>6} {kind:>14} {med / n_meas * 1e6:10.1f} {spread:>22} {ins_s:>22} {med / base:9.2f} "
                  f"{statistics.median(closing[kind]) * 1e3:9.0f}")
            out[f"{kind}_{n_targets}_sink_us_per_meas"] = statistics.median(share)
            out[f"{kind}_{n_targets}_in_sink_us_per_meas"] = statistics.median(ins)
    return out


if __name__ == "__main__":
    run(quick="--quick" in sys.argv)
