"""The service's per-measurement work outside the scan, stage by stage, this tree against another
(issue 11 goal 1), in CPU time (time.process_time).

Load: bench.e2e_load.Scene over T targets, the shipped configuration (configs/service.toml),
batches of intake.batch_max records, arrival = sensor time + 1 ms. Stages, as the shipped
service runs them:
  edge      Pipeline.ingest with the tracker's `process` stubbed (empty result): routing,
            decoding, the key and future checks, latency and gap statistics;
  admit     Tracker._admit of each batch's detections, on a new tracker (validation, clocks,
            window, duplicates);
  stream    RotatingStream.write_many of each batch (the .fstream);
  publish   Service._step with the pipeline's output replayed (what the real pipeline gave for
            the load): the estimate encoding, the publishers' puts (a dummy session), events;
  select    PublishedView.select and prune over the same outputs.
Each stage: the fastest of `reps` passes in a child process (the least disturbed on a loaded
machine); the trees' children interleaved, `repeats` times; printed: median [min-max] over the
repeats of CPU us per measurement, and this / other.

    python -m bench.intake_stages OTHER_TREE [targets] [seconds] [repeats]
"""

from __future__ import annotations

import itertools
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
STAGES = ("edge", "admit", "stream", "publish", "select")


class _Pub:
    def put(self, payload: bytes) -> None: ...

    def undeclare(self) -> None: ...


class _Session:
    def declare_publisher(self, key: str, **kw: Any) -> _Pub:
        return _Pub()

    def put(self, *a: Any, **kw: Any) -> None: ...

    def close(self) -> None: ...


def _child(tree: str, targets: int, seconds: float, reps: int) -> dict[str, float]:
    sys.path[:0] = [tree]
    import msgspec

    from bench.e2e_load import SENSORS, Scene
    from fusion import messages as m
    from fusion.config import load_service_config
    from fusion.io import wire
    from fusion.io.stream_rotation import RotatingStream
    from fusion.pipeline import Output, Pipeline
    from fusion.publication import PublishedView
    from fusion.service import Service
    from fusion.tracking.results import StepResult
    from fusion.tracking.tracker import Tracker

    assert Path(m.__file__).resolve().is_relative_to(Path(tree).resolve()), m.__file__
    cfg = load_service_config(Path(tree) / "configs" / "service.toml")
    cfg = msgspec.structs.replace(cfg, recording=msgspec.structs.replace(cfg.recording, enabled=False))
    t0 = 1 << 60
    keys = [m.meas_key(cfg.namespace, s) for s in SENSORS]
    ticks = itertools.takewhile(lambda tick: tick[0] - t0 < seconds * 1e9, Scene(targets, 1).ticks(t0))
    recs = [(t + 1_000_000, keys[s], p) for t, s, ps in ticks for p in ps]
    n, bm = len(recs), cfg.intake.batch_max
    batches = [recs[i:i + bm] for i in range(0, n, bm)]
    out: dict[str, float] = {"measurements": n}

    def timed(name: str, f: Any, setup: Any = lambda: None) -> None:
        best = float("inf")
        for _ in range(reps):
            arg = setup()
            a = time.process_time()
            f(arg)
            best = min(best, time.process_time() - a)
        out[name] = best / n * 1e6

    empty = StepResult((), (), (), 0, (), ())

    def edge() -> Pipeline:
        tr = Tracker(cfg.tracker)
        tr.process = lambda items: (list(items), empty)[1]  # type: ignore[method-assign]
        return Pipeline(tr, wire.Codec(cfg.namespace), max_future_wall_ns=10**18)

    timed("edge", lambda p: [p.ingest(b) for b in batches], edge)
    real = Pipeline(Tracker(cfg.tracker), wire.Codec(cfg.namespace))
    dets = []
    for b in batches:  # the detections the tracker is handed, batch by batch
        got: list[Any] = []
        real.tracker.process = lambda items, got=got: (got.extend(items), empty)[1]  # type: ignore[method-assign]
        real.ingest(b)
        dets.append(got)
    timed("admit", lambda tr: [tr._admit(d) for d in dets], lambda: Tracker(cfg.tracker))
    with tempfile.TemporaryDirectory() as tmp:
        files = iter(range(reps))
        timed("stream", lambda st: [st.write_many(b) for b in batches],
              lambda: RotatingStream(Path(tmp) / f"s{next(files)}.fstream", namespace="b", rotate_bytes=10**12))
    real = Pipeline(Tracker(cfg.tracker), wire.Codec(cfg.namespace))
    outs = [real.ingest(b) for b in batches]
    results = [o.result for o in outs]

    def service() -> Service:
        svc = Service(cfg)
        svc.session = _Session()
        svc.outbox.open(svc.session)  # as Service.open does once its session is open
        it = iter(outs)
        svc.pipeline.ingest = lambda batch, **_: next(it)  # type: ignore[method-assign]  # (more=, prune=)
        return svc

    timed("publish", lambda svc: [svc._step(b) for b in batches], service)
    tracker = real.tracker

    def select(v: PublishedView) -> None:
        for r in results:
            v.select(r.estimates)
            v.select_events(r.events)
            v.prune(tracker.horizon_ns, tracker.track_set)

    timed("select", select, PublishedView)
    out["published"] = sum(len(o.to_publish) for o in outs)
    assert isinstance(outs[0], Output)
    return out


def run(other: str, *, targets: int = 100, seconds: float = 4.0, repeats: int = 3, reps: int = 3) -> dict[str, Any]:
    print(f"intake stages: {targets} targets, {seconds:g} s of the shipped load, CPU us per measurement, "
          f"{REPO} against {other}, {repeats} interleaved repeats (fastest of {reps} passes each)")
    trees = {"this": str(REPO), "other": other}
    got: dict[str, list[dict[str, float]]] = {k: [] for k in trees}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            for name, tree in trees.items():
                res = subprocess.run([sys.executable, __file__, "--child", tree, str(targets), str(seconds), str(reps)],
                                     capture_output=True, text=True, check=True, cwd=tmp)
                got[name].append(json.loads(res.stdout.strip().splitlines()[-1]))
    table: dict[str, Any] = {"targets": targets, "measurements": got["this"][0]["measurements"],
                             "published": got["this"][0]["published"]}
    print(f"  {'stage':8s} {'this':>20s} {'other':>20s} {'this/other':>10s}")
    for stage in (*STAGES, "total"):
        row = {}
        for name in trees:
            v = [sum(r[s] for s in STAGES) if stage == "total" else r[stage] for r in got[name]]
            row[name] = (statistics.median(v), min(v), max(v))
        table[stage] = row
        cells = [f"{row[k][0]:6.2f} [{row[k][1]:.2f}-{row[k][2]:.2f}]" for k in trees]
        print(f"  {stage:8s} {cells[0]:>20s} {cells[1]:>20s} {row['this'][0] / row['other'][0]:10.2f}")
    return table


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        print(json.dumps(_child(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]))))
    else:
        a = sys.argv[1:]
        run(a[0], targets=int(a[1]) if len(a) > 1 else 100, seconds=float(a[2]) if len(a) > 2 else 4.0,
            repeats=int(a[3]) if len(a) > 3 else 3)
