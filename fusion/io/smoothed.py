"""Smoothed tracks into a recording, beside the filtered ones (`fusion replay --smooth`).

Entities, on the recording's sensor-time timeline `t` (the one fusion.io.rerun_sink writes):
  tracks/<track_id>/smoothed/state   x_k|N, one named series per state component (Scalars)
  tracks/<track_id>/smoothed/std     sqrt(diag(P_k|N))
  tracks/<track_id>/smoothed/error   x_k|N - truth, where a truth was matched (fusion.smoothing)
Written with one `send_columns` per entity (fusion.smoothing.Smoothed holds whole tracks).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.smoothing import SmoothedTrack


def _series(rec: Any, entity: str, names: tuple[str, ...], t_ns: Array, values: Array) -> None:
    import rerun as rr

    rec.log(entity, rr.SeriesLines(names=list(names)), static=True)
    rec.send_columns(entity, indexes=[rr.TimeColumn("t", timestamp=t_ns.astype("datetime64[ns]"))],
                     columns=rr.Scalars.columns(scalars=values.ravel()).partition([values.shape[1]] * len(values)))


def log_smoothed(rec: Any, tracks: tuple[SmoothedTrack, ...], layout: tuple[str, ...]) -> int:
    """Log every smoothed track to the RecordingStream `rec`; returns the rows written."""
    rows = 0
    for t in tracks:
        base = f"tracks/{t.track_id}/smoothed"
        _series(rec, f"{base}/state", layout, t.t_ns, t.x_smooth)
        std = np.sqrt(np.clip(np.diagonal(t.P_smooth, axis1=1, axis2=2), 0.0, None))
        _series(rec, f"{base}/std", layout, t.t_ns, std)
        rows += 2 * len(t.t_ns)
        ok = ~np.isnan(t.truth[:, 0])
        if ok.any():
            _series(rec, f"{base}/error", layout, t.t_ns[ok], t.x_smooth[ok] - t.truth[ok])
            rows += int(ok.sum())
    return rows
