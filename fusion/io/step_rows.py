"""The rows a RerunSink makes of the steps logged since its last flush (fusion.io.rerun_sink
keeps each step's measurements and associations as they are and calls these at the flush):

- `associations`: one record/associations block of every association of those steps (its
  sensor, seq, outcome, the track's short label, the labels of the tracks it gated with, NIS);
- `measured_points`: world/meas/<sensor>, one row per step, sensor and scan time, in step then
  scan-time order, each point coloured by its association's outcome in that step (associated:
  it updated a track; else clutter).

`steps`: (measurements, associations, step, arrival_ns or None (then each row's t_ns)).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pyarrow as pa

from fusion.io.columns import Ragged, stack
from fusion.io.derive import world
from fusion.io.labels import short_id
from fusion.io.palette import colour
from fusion.tracking.results import Outcome

Step = tuple[tuple, tuple, int, int | None]
_USED = (Outcome.UPDATED,)  # a measurement that started a track is not drawn as associated
_SEQ_MASK = (1 << 64) - 1
_RGBA_USED = np.array(colour("associated"), dtype=np.uint8)
_RGBA_CLUTTER = np.array(colour("clutter"), dtype=np.uint8)


def associations(steps: Sequence[Step], sink: Any) -> None:
    """Every association of `steps` as one block of record/associations rows."""
    A = [a for _, As, _, _ in steps for a in As]
    if not A:
        return
    step_a: list[int] = []
    arr_a: list[int] = []
    for _, As, step, arr in steps:
        step_a += [step] * len(As)
        arr_a += [a.t_ns for a in As] if arr is None else [arr] * len(As)
    gated = [a.gated for a in A]
    flat = [short_id(g) for gs in gated for g in gs]
    offsets = np.zeros(len(A) + 1, dtype=np.int32)
    np.cumsum([len(gs) for gs in gated], out=offsets[1:])
    sink.col("record/associations", "record").extend(
        [a.t_ns for a in A], step_a, arr_a, sensor=[a.sensor_id for a in A], seq=[a.seq for a in A],
        outcome=[a.outcome for a in A],  # an Outcome is a str (StrEnum): arrow takes its value as it is
        label=["" if a.track_id is None else short_id(a.track_id) for a in A],
        gated=pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, pa.string())),
        nis=np.array([a.nis for a in A], dtype=np.float64))  # None (a birth's, clutter's) as NaN


def measured_points(steps: Sequence[Step], sink: Any) -> None:
    """The measured points of `steps`, per sensor (see the module docstring). A step's
    measurements are taken per sensor in blocks (one sensor per step, as a scan is, but any mix
    is split); a point is associated when an association of its step, sensor and seq is _USED."""
    by_sensor: dict[str, tuple[list[int], list[Any], list[int | None], list[bool]]] = {}
    for ms, As, step, arr in steps:
        if not ms:
            continue
        first = ms[0].sensor_id
        if all(m.sensor_id == first for m in ms):
            groups: Any = ((first, ms),)
        else:
            split: dict[str, list[Any]] = {}
            for m in ms:
                split.setdefault(m.sensor_id, []).append(m)
            groups = split.items()
        for sensor_id, g in groups:
            b = by_sensor.get(sensor_id)
            if b is None:
                b = by_sensor[sensor_id] = ([], [], [], [])
            used_seqs = {a.seq & _SEQ_MASK for a in As if a.outcome in _USED and a.sensor_id == sensor_id}
            b[0].extend([step] * len(g))
            b[1].extend(g)
            b[2].extend([arr] * len(g))
            b[3].extend([(m.seq & _SEQ_MASK) in used_seqs for m in g] if used_seqs else [False] * len(g))
    for sensor_id in sorted(by_sensor):
        steps_m, ms_, arrs, used_m = by_sensor[sensor_id]
        step_m = np.array(steps_m, dtype=np.int64)
        t_m = np.fromiter((m.t_ns for m in ms_), dtype=np.int64, count=len(ms_))
        order = np.lexsort((t_m, step_m))  # by step, then scan time; stable: a scan's order kept
        used = np.array(used_m, dtype=bool)[order]
        step_m, t_m = step_m[order], t_m[order]
        P = world(stack([m.position for m in ms_])[order])  # one sensor: one shape
        first_r = np.flatnonzero(np.r_[True, (step_m[1:] != step_m[:-1]) | (t_m[1:] != t_m[:-1])])
        lens = np.diff(np.r_[first_r, len(ms_)])
        t_r = t_m[first_r]
        arr_r = [arrs[i] for i in order[first_r].tolist()]
        arr_m = np.array([t if a is None else a for t, a in zip(t_r.tolist(), arr_r, strict=True)], dtype=np.int64)
        rgba = np.where(used[:, None], _RGBA_USED, _RGBA_CLUTTER).astype(np.uint8)
        sink.col(f"world/meas/{sensor_id}", "points", radius=-1.75).extend(
            t_r, step_m[first_r], arr_m, p=Ragged(P, lens), rgba=Ragged(rgba, lens))
