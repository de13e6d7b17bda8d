"""The recording's cost inside the sink, A/B in one process: the sink calls of bench.recording_cost's
load (shipped configuration, truth of every target at every radar scan) captured once, then fed to
this tree's RerunSink and to another tree's (e.g. a `git worktree add --detach /tmp/main main`),
alternating, with the same record-flush cadence (at FLUSH_ROWS pending rows, the sink's own
threshold, instead of the wall clock: the same flushes for both, ~0.5 s of the bench's run) and
one view flush at close, as a short run of the bench has. Reported: thread CPU per measurement,
median [min, max] over the repeats.

    python -m bench.recording_replay OTHER_TREE [targets ...] [--repeats N]

The other tree's fusion.io modules are loaded under their own names for the time of the import
(its rerun_sink with its own columns, step_rows, track_rows...): both sinks run in this process,
on the same StepResults, so the machine's load falls on both alike.
"""

from __future__ import annotations

import importlib
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import fusion.io
from bench import recording_cost as rc
from fusion.io.gc_tuning import settle_garbage_collector
from fusion.io.rerun_sink import RerunSink

# pending rows per record flush (~2.7 rows per measurement: estimate, association, truth, scans)
FLUSH_ROWS = {10: 4000, 100: 16000, 1000: 16000}


def load_sink(root: str) -> type:
    """RerunSink of the tree at `root`, its fusion.io modules imported apart from this tree's."""
    saved = {n: sys.modules.pop(n) for n in list(sys.modules) if n.startswith("fusion.io.")}
    attrs = {k: v for k, v in vars(fusion.io).items() if "fusion.io." + k in saved}
    for k in attrs:
        delattr(fusion.io, k)
    old = list(fusion.io.__path__)
    fusion.io.__path__[:] = [str(Path(root) / "fusion" / "io")]
    try:
        mod = importlib.import_module("fusion.io.rerun_sink")
    finally:
        for n in [n for n in sys.modules if n.startswith("fusion.io.")]:
            sys.modules.pop(n)
        fusion.io.__path__[:] = old
        sys.modules.update(saved)
        for k, v in attrs.items():
            setattr(fusion.io, k, v)
    assert mod.track_rows.__file__.startswith(str(Path(root).resolve())) or mod.track_rows.__file__.startswith(root)
    return mod.RerunSink


def capture(n_targets: int) -> tuple[list[tuple[int, Any, Any]], Any, Any, int]:
    """The sink calls of the bench's load at n_targets: (kind, args, arrival), the tracker, the config."""
    cfg = rc.load_service_config(rc.CONFIG)
    data = rc.batches(n_targets, (rc.WARM_S + rc.MEASURED_S) * rc.RATE[n_targets] / (rc.PER_S * n_targets),
                      ns=cfg.namespace)
    calls: list[tuple[int, Any, Any]] = []

    class Capture:
        def log_step(self, r: Any, *, arrival_ns: int | None = None) -> None:
            calls.append((0, r, arrival_ns))

        def log_truths(self, *a: Any) -> None:
            calls.append((1, a, None))

        def log_text(self, *a: Any) -> None:
            calls.append((2, a, None))

        def maybe_flush(self) -> None:
            pass

        def close(self) -> None:
            pass

    tr = rc.Tracker(cfg.tracker)
    pipe = rc.Pipeline(tr, rc.wire.Codec(cfg.namespace))
    pipe.sink = Capture()
    for recs in data:
        pipe.ingest(recs)
    return calls, tr, cfg, tr.counts.applied


def once(cls: type, calls: list, tr: Any, cfg: Any, flush_rows: int, d: Path) -> float:
    """Thread CPU seconds of feeding `calls` to a new sink of class `cls`, its close included."""
    s = cls(d / "r.rrd", layout=tr.layout, position_indices=tr.position_indices,
            velocity_indices=tr.velocity_indices, flush_interval_s=1e9, view_interval_s=1e9, flush_rows=flush_rows,
            meta={"namespace": cfg.namespace, "modes": list(rc.mode_names(cfg.tracker))})
    a = time.thread_time()
    for kind, r, arr in calls:
        if kind == 0:
            s.log_step(r, arrival_ns=arr)
        elif kind == 1:
            s.log_truths(*r)
        else:
            s.log_text(*r)
    s.close()
    return time.thread_time() - a


def main(argv: list[str]) -> None:
    repeats = 5
    if "--repeats" in argv:
        k = argv.index("--repeats")
        repeats = int(argv[k + 1])
        argv = argv[:k] + argv[k + 2:]
    other = argv[0]
    sizes = [int(a) for a in argv[1:] if a.isdigit()] or [10, 100, 1000]
    settle_garbage_collector()
    sinks = {"other": load_sink(other), "this": RerunSink}
    assert sinks["other"] is not RerunSink
    print(f"inside the sink, thread CPU us/meas, median [min, max] of {repeats} interleaved repeats; other = {other}")
    for n in sizes:
        calls, tr, cfg, n_meas = capture(n)
        out: dict[str, list[float]] = {k: [] for k in sinks}
        with tempfile.TemporaryDirectory() as d:
            for k, cls in sinks.items():  # warm: imports, first files
                once(cls, calls, tr, cfg, FLUSH_ROWS[n], Path(d) / f"w{k}")
            for r in range(repeats):
                for k, cls in sinks.items():
                    out[k].append(once(cls, calls, tr, cfg, FLUSH_ROWS[n], Path(d) / f"{k}{r}") / n_meas * 1e6)
        print(f"{n:>5} targets, {n_meas} meas: " + "   ".join(
            f"{k} {statistics.median(v):.2f} [{min(v):.2f}, {max(v):.2f}]" for k, v in out.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
