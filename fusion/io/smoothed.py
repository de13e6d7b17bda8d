"""Smoothed tracks into a recording, beside the filtered ones (`fusion replay --smooth`).

Entities, on the recording's sensor-time timeline `t` (the one fusion.io.rerun_sink writes, and of
its kind: a duration from the stream's start, or an epoch timestamp), under the track's short
label (fusion.io.labels.short_id, as the sink's own tracks/<label>/... entities):
  tracks/<label>/smoothed/state   x_k|N, one named series per state component (Scalars)
  tracks/<label>/smoothed/std     sqrt(diag(P_k|N))
  tracks/<label>/smoothed/error   x_k|N - truth, where a truth was matched (fusion.smoothing)
and, so that the per-track views of the filtered track (fusion.io.blueprint.TRACK_VIEWS, origin
tracks/<label>/<role>, query $origin/**) show the smoothed series beside the filtered ones, per
position axis `a` (with `position_indices`):
  tracks/<label>/position/<a>/smoothed   x_k|N on that axis ("smoothed")
  tracks/<label>/error/<a>/smoothed      x_k|N - truth with +-2 sqrt(P_k|N) on that axis
  tracks/<label>/std/smoothed            sqrt(diag(P_k|N)) ("smoothed sigma <component>")
Written with one `send_columns` per entity (fusion.smoothing.Smoothed holds whole tracks).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fusion.core.checks import Array
from fusion.io.arrow_columns import time_index
from fusion.io.labels import is_epoch, short_id
from fusion.io.palette import colour, series_colours
from fusion.smoothing import SmoothedTrack


def _series(rec: Any, entity: str, names: Sequence[str], t_ns: Array, values: Array, epoch: bool,
            colours: Sequence[tuple[int, int, int, int]] | None = None, width: float = 2.0) -> None:
    import rerun as rr

    style = rr.SeriesLines(names=list(names)) if colours is None else \
        rr.SeriesLines(names=list(names), colors=[list(c) for c in colours], widths=[width] * len(names))
    rec.log(entity, style, static=True)
    rec.send_columns(entity, indexes=[time_index("t", t_ns, epoch=epoch)],
                     columns=rr.Scalars.columns(scalars=values.ravel()).partition([values.shape[1]] * len(values)))


def log_smoothed(rec: Any, tracks: tuple[SmoothedTrack, ...], layout: tuple[str, ...], *,
                 epoch: bool | None = None, position_indices: Sequence[int] = ()) -> int:
    """Log every smoothed track to the RecordingStream `rec`; returns the rows written. epoch:
    the kind of the recording's `t` (RerunSink.epoch_time; None: decided from the times as the
    sink does, fusion.io.labels.is_epoch). position_indices: the state's position components,
    whose axes get the per-view entities of the module docstring (none without)."""
    if epoch is None:
        firsts = [int(t.t_ns[0]) for t in tracks if len(t.t_ns)]
        epoch = bool(firsts) and is_epoch(min(firsts))
    rows = 0
    for t in tracks:
        lab = short_id(t.track_id)
        base = f"tracks/{lab}/smoothed"
        _series(rec, f"{base}/state", layout, t.t_ns, t.x_smooth, epoch)
        std = np.sqrt(np.clip(np.diagonal(t.P_smooth, axis1=1, axis2=2), 0.0, None))
        _series(rec, f"{base}/std", layout, t.t_ns, std, epoch)
        rows += 2 * len(t.t_ns)
        ok = ~np.isnan(t.truth[:, 0])
        if ok.any():
            _series(rec, f"{base}/error", layout, t.t_ns[ok], t.x_smooth[ok] - t.truth[ok], epoch)
            rows += int(ok.sum())
        if position_indices:
            rows += _beside_filtered(rec, lab, t, std, ok, layout, list(position_indices), epoch)
    return rows


def _beside_filtered(rec: Any, lab: str, t: SmoothedTrack, std: Array, ok: Array, layout: tuple[str, ...],
                     pi: list[int], epoch: bool) -> int:
    """The per-axis entities inside the filtered track's views (see the module docstring)."""
    rows = 0
    _series(rec, f"tracks/{lab}/std/smoothed", [f"smoothed sigma {x}" for x in layout], t.t_ns, std, epoch,
            series_colours(len(layout)))
    for i in pi:
        ax = layout[i]
        _series(rec, f"tracks/{lab}/position/{ax}/smoothed", ["smoothed"], t.t_ns, t.x_smooth[:, i:i + 1], epoch,
                [colour("smoothed")], width=1.5)  # drawn after the estimate (2.5 wide): both show
        rows += len(t.t_ns)
        if ok.any():
            e = t.x_smooth[ok, i] - t.truth[ok, i]
            s2 = 2.0 * std[ok, i]
            _series(rec, f"tracks/{lab}/error/{ax}/smoothed", ["smoothed error", "smoothed +2 sigma",
                                                                "smoothed -2 sigma"],
                    t.t_ns[ok], np.column_stack([e, s2, -s2]), epoch,
                    [colour("smoothed"), colour("smoothed_bound"), colour("smoothed_bound")])
            rows += int(ok.sum())
    return rows + len(t.t_ns)
