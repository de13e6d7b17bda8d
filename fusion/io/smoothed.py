"""Smoothed tracks into a recording, beside the filtered ones (`fusion replay --smooth`).

Entities, on the recording's sensor-time timeline `t` (the one fusion.io.rerun_sink writes, and of
its kind: a duration from the stream's start, or an epoch timestamp), under the track's short
label (fusion.io.labels.short_id, as the sink's own tracks/<label>/... entities):
  tracks/<label>/smoothed/state   x_k|N, one named series per state component (Scalars)
  tracks/<label>/smoothed/std     sqrt(diag(P_k|N))
  tracks/<label>/smoothed/error   x_k|N - truth, where a truth was matched (fusion.smoothing)
Written with one `send_columns` per entity (fusion.smoothing.Smoothed holds whole tracks).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.io.columns import time_column
from fusion.io.labels import is_epoch, short_id
from fusion.smoothing import SmoothedTrack


def _series(rec: Any, entity: str, names: tuple[str, ...], t_ns: Array, values: Array, epoch: bool) -> None:
    import rerun as rr

    rec.log(entity, rr.SeriesLines(names=list(names)), static=True)
    rec.send_columns(entity, indexes=[time_column(rr, "t", t_ns.tolist(), epoch=epoch)],
                     columns=rr.Scalars.columns(scalars=values.ravel()).partition([values.shape[1]] * len(values)))


def log_smoothed(rec: Any, tracks: tuple[SmoothedTrack, ...], layout: tuple[str, ...], *,
                 epoch: bool | None = None) -> int:
    """Log every smoothed track to the RecordingStream `rec`; returns the rows written. epoch:
    the kind of the recording's `t` (RerunSink.epoch_time; None: decided from the times as the
    sink does, fusion.io.labels.is_epoch)."""
    if epoch is None:
        firsts = [int(t.t_ns[0]) for t in tracks if len(t.t_ns)]
        epoch = bool(firsts) and is_epoch(min(firsts))
    rows = 0
    for t in tracks:
        base = f"tracks/{short_id(t.track_id)}/smoothed"
        _series(rec, f"{base}/state", layout, t.t_ns, t.x_smooth, epoch)
        std = np.sqrt(np.clip(np.diagonal(t.P_smooth, axis1=1, axis2=2), 0.0, None))
        _series(rec, f"{base}/std", layout, t.t_ns, std, epoch)
        rows += 2 * len(t.t_ns)
        ok = ~np.isnan(t.truth[:, 0])
        if ok.any():
            _series(rec, f"{base}/error", layout, t.t_ns[ok], t.x_smooth[ok] - t.truth[ok], epoch)
            rows += int(ok.sum())
    return rows
