"""`fusion replay`: a recorded stream through the same pipeline as the live service.

Deterministic: the tracker's output depends only on the samples and their arrival order, so a
replay gives the estimates the live service published (latest revision per track, time and
sensor), and two replays give identical estimates.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fusion import messages as m
from fusion.config import ServiceConfig, load_service_config
from fusion.errors import ConfigError
from fusion.io import wire
from fusion.io.rerun_sink import RerunSink
from fusion.io.streamfile import read_records
from fusion.pipeline import Pipeline
from fusion.tracking.results import Counts
from fusion.tracking.tracker import Tracker

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


@dataclass(frozen=True)
class ReplayCounts:
    records: int
    estimates: int
    counts: Counts  # the pipeline's counts (applied, refused by reason, ...)


def _config_for(path: Path | None, namespace: str) -> ServiceConfig:
    """A service config: the file given (service or scenario TOML), or the scenario whose
    namespace the stream was recorded under."""
    if path is not None:
        return load_service_config(path)
    for p in sorted((CONFIGS / "scenarios").glob("*.toml")):
        cfg = load_service_config(p)
        if cfg.namespace == namespace:
            return cfg
    raise ConfigError(f"no configuration for namespace {namespace!r}: pass --config")


def replay(stream: str | Path, *, config: str | Path | None = None, out: str | Path | None = None,
           estimates: str | Path | None = None, realtime: bool = False,
           progress: Callable[[int, int], None] | None = None, batch: int = 1000) -> ReplayCounts:
    """Replay `stream` (.fstream or .jsonl); write a recording to `out` and estimates to a .jsonl.
    `progress(done, total)` is called after every batch of records (for a progress bar). Files
    are closed complete even when interrupted (KeyboardInterrupt propagates)."""
    records, meta = read_records(stream)
    ns = str(meta.get("namespace", "demo"))
    cfg = _config_for(Path(config) if config else None, ns)
    tracker = Tracker(cfg.tracker)
    sink = None
    if out is not None:
        sink = RerunSink(out, recording_id=Path(out).stem, layout=tracker.layout,
                         position_indices=tracker.position_indices, velocity_indices=tracker.velocity_indices,
                         meta={"namespace": ns, "replay_of": str(stream)}, counts=lambda: pipe.counts().flat())
    pipe = Pipeline(tracker, wire.Codec(ns), sink=sink,
                    max_future_wall_ns=round(cfg.intake.max_future_wall_s * 1e9),
                    publish_tentative=cfg.publish_tentative)
    est_file = Path(estimates).open("wb") if estimates else None  # noqa: SIM115 - closed in finally
    enc = wire.estimate_encoder(tracker.layout, tracker.model_name)
    all_records = list(records)
    n_est = 0
    t_wall0, a0 = time.monotonic(), all_records[0][0] if all_records else 0
    try:
        i = 0
        while i < len(all_records):
            if realtime:
                # one record at a time, at its recorded arrival time relative to the first
                due = t_wall0 + (all_records[i][0] - a0) / 1e9
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                chunk = all_records[i:i + 1]
            else:
                chunk = all_records[i:i + batch]
            i += len(chunk)
            res = pipe.ingest(chunk)
            for e in res.to_publish:
                n_est += 1
                if est_file is not None:
                    est_file.write(m.encode_json(m.decode_estimate(enc(e))) + b"\n")
            if progress is not None:
                progress(i, len(all_records))
    finally:
        if est_file is not None:
            est_file.close()
        if sink is not None:
            sink.close()
    return ReplayCounts(len(all_records), n_est, pipe.counts())
