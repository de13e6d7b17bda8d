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
    step_a = [step for _, As, step, _ in steps for _ in As]
    t_a = [a.t_ns for a in A]
    arr_a = [t if arr is None else arr for (_, As, _, arr) in steps for t in [a.t_ns for a in As]]
    gated = [a.gated for a in A]
    flat = [short_id(g) for gs in gated for g in gs]
    offsets = np.zeros(len(A) + 1, dtype=np.int32)
    np.cumsum([len(gs) for gs in gated], out=offsets[1:])
    sink.col("record/associations", "record").extend(
        t_a, step_a, arr_a, sensor=[a.sensor_id for a in A], seq=[a.seq for a in A],
        outcome=[a.outcome.value for a in A],
        label=["" if a.track_id is None else short_id(a.track_id) for a in A],
        gated=pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat, pa.string())),
        nis=[np.nan if a.nis is None else float(a.nis) for a in A])


def measured_points(steps: Sequence[Step], sink: Any) -> None:
    """The measured points of `steps`, per sensor (see the module docstring)."""
    # the measurements an association used (_USED) in their step, per sensor: step << 64 | seq
    used_keys: dict[str, set[int]] = {}
    for _, As, step, _ in steps:
        for a in As:
            if a.outcome in _USED:
                used_keys.setdefault(a.sensor_id, set()).add((step << 64) | (a.seq & _SEQ_MASK))
    by_sensor: dict[str, tuple[list[int], list[Any], list[int | None]]] = {}
    for ms, _, step, arr in steps:
        for m in ms:
            b = by_sensor.get(m.sensor_id)
            if b is None:
                b = by_sensor[m.sensor_id] = ([], [], [])
            b[0].append(step)
            b[1].append(m)
            b[2].append(arr)
    for sensor_id in sorted(by_sensor):
        steps_m, ms_, arrs = by_sensor[sensor_id]
        step_m = np.array(steps_m, dtype=np.int64)
        t_m = np.fromiter((m.t_ns for m in ms_), dtype=np.int64, count=len(ms_))
        order = np.lexsort((t_m, step_m))  # by step, then scan time; stable: a scan's order kept
        keys = used_keys.get(sensor_id, set())
        used = np.fromiter(((s << 64) | (m.seq & _SEQ_MASK) in keys for s, m in zip(steps_m, ms_, strict=True)),
                           dtype=bool, count=len(ms_))[order]
        step_m, t_m = step_m[order], t_m[order]
        P = world(stack([m.position for m in ms_])[order])  # one sensor: one shape
        first = np.flatnonzero(np.r_[True, (step_m[1:] != step_m[:-1]) | (t_m[1:] != t_m[:-1])])
        lens = np.diff(np.r_[first, len(ms_)])
        t_r = t_m[first]
        arr_r = [arrs[i] for i in order[first].tolist()]
        arr_m = np.array([t if a is None else a for t, a in zip(t_r.tolist(), arr_r, strict=True)], dtype=np.int64)
        rgba = np.where(used[:, None], _RGBA_USED, _RGBA_CLUTTER).astype(np.uint8)
        sink.col(f"world/meas/{sensor_id}", "points", radius=-1.75).extend(
            t_r, step_m[first], arr_m, p=Ragged(P, lens), rgba=Ragged(rgba, lens))
