"""`fusion replay`: a recorded stream through the same pipeline as the live service.

Deterministic: the tracker's output depends only on the samples and their arrival order, so a
replay gives the estimates the live service published (latest revision per track, time and
sensor), and two replays give identical estimates.

With `smooth`, every track that was ever confirmed is also smoothed over its whole life by the
fixed-interval RTS smoother (fusion.smoothing), and the smoothed estimates are written into the
same recording beside the filtered ones (fusion.io.smoothed); the position RMSE against the
truth, filtered and smoothed over the same rows, is returned. The smoother needs every track's
whole history: memory grows with the stream (it is a review tool, not for endless streams).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from fusion import messages as m
from fusion.config import ServiceConfig, load_service_config, mode_names
from fusion.errors import ConfigError
from fusion.io import wire
from fusion.io.gain_groups import measured_components
from fusion.io.rerun_sink import RerunSink
from fusion.io.smoothed import log_smoothed
from fusion.io.streamfile import read_records
from fusion.pipeline import Pipeline
from fusion.smoothing import Histories, position_rmse
from fusion.smoothing import smooth as smooth_tracks
from fusion.tracking.results import Counts
from fusion.tracking.tracker import Tracker

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


@dataclass(frozen=True)
class ReplayCounts:
    records: int
    estimates: int
    counts: Counts  # the pipeline's counts (applied, refused by reason, ...)
    smoothed_tracks: int = 0  # with smooth=True
    smoothing_failed: tuple[tuple[int, str], ...] = ()  # (track id, why)
    rmse_filtered_m: float | None = None  # position RMSE vs truth, over the smoothed tracks' matched rows
    rmse_smoothed_m: float | None = None
    config: Path | None = None  # the configuration the stream was replayed with


def _config_for(path: Path | None, namespace: str) -> tuple[ServiceConfig, Path]:
    """A service config and its file: the file given (service or scenario TOML), or the
    scenario whose namespace the stream was recorded under."""
    if path is not None:
        return load_service_config(path), path
    for p in sorted((CONFIGS / "scenarios").glob("*.toml")):
        cfg = load_service_config(p)
        if cfg.namespace == namespace:
            return cfg, p
    raise ConfigError(f"no configuration for namespace {namespace!r}: pass --config")


def replay(stream: str | Path, *, config: str | Path | None = None, out: str | Path | None = None,
           estimates: str | Path | None = None, realtime: bool = False,
           progress: Callable[[int, int], None] | None = None, batch: int = 1000,
           smooth: bool = False) -> ReplayCounts:
    """Replay `stream` (.fstream or .jsonl); write a recording to `out` and estimates to a .jsonl;
    with `smooth`, smoothed tracks too (see the module docstring).
    `progress(done, total)` is called after every batch of records (for a progress bar). Files
    are closed complete even when interrupted (KeyboardInterrupt propagates)."""
    records, meta = read_records(stream)
    ns = str(meta.get("namespace", "demo"))
    cfg, cfg_path = _config_for(Path(config) if config else None, ns)
    tracker = Tracker(cfg.tracker)
    sink = None
    if out is not None:
        sink = RerunSink(out, recording_id=Path(out).stem, layout=tracker.layout,
                         position_indices=tracker.position_indices, velocity_indices=tracker.velocity_indices,
                         meta={"namespace": ns, "replay_of": str(stream), "modes": mode_names(cfg.tracker),
                               "measured": measured_components(tracker.sensors, tracker.layout)},
                         counts=lambda: pipe.counts().flat())
    hist = Histories(sink) if smooth else None
    pipe = Pipeline(tracker, wire.Codec(ns), sink=hist if hist is not None else sink,
                    max_future_wall_ns=round(cfg.intake.max_future_wall_s * 1e9),
                    publish_tentative=cfg.publish_tentative)
    est_file = Path(estimates).open("wb") if estimates else None  # noqa: SIM115 - closed in finally
    enc = wire.estimate_encoder(tracker.layout, tracker.model_name)
    all_records = list(records)
    n_est = 0
    sm = None
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
            res = pipe.ingest(chunk, more=not realtime and i < len(all_records))  # a scan cut by the batch waits
            for e in res.to_publish:
                n_est += 1
                if est_file is not None:
                    est_file.write(m.encode_json(m.decode_estimate(enc(e))) + b"\n")
            if progress is not None:
                progress(i, len(all_records))
        if hist is not None:
            sm = smooth_tracks(hist, tracker)
            if sink is not None:
                sink.flush()  # the recording's time kinds are settled by its first rows
                log_smoothed(sink.rec, sm.tracks, tracker.layout, epoch=sink.epoch_time,
                             position_indices=tracker.position_indices)
                for tid, why in sm.failed:
                    sink.log_text(tracker.now_ns or 0, f"track {tid} not smoothed: {why}", "WARN")
    finally:
        if est_file is not None:
            est_file.close()
        if sink is not None:
            sink.close()
    if sm is None:
        return ReplayCounts(len(all_records), n_est, pipe.counts(), config=cfg_path)
    rf, rs = position_rmse(sm.tracks, tracker.position_indices)
    return ReplayCounts(len(all_records), n_est, pipe.counts(), len(sm.tracks), sm.failed, rf, rs, config=cfg_path)
