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
from itertools import chain
from operator import itemgetter
from typing import Any

import numpy as np
import pyarrow as pa

from fusion.io.columns import Ragged
from fusion.io.derive import world
from fusion.io.labels import short_id
from fusion.io.palette import colour
from fusion.tracking.results import Outcome, ScanPoints

Step = tuple[tuple, tuple, int, int | None]
_USED = (Outcome.UPDATED,)  # a measurement that started a track is not drawn as associated
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
    """The measured points of `steps`, per sensor (see the module docstring): one row per scan
    (fusion.tracking.results.ScanPoints: one sensor, one time), in step then scan-time order; a
    point is associated when an association of its step and sensor with its seq is _USED."""
    by_sensor: dict[str, list[tuple[int, int, int, ScanPoints, list[bool]]]] = {}
    for ms, As, step, arr in steps:
        used_seqs: dict[str, set[int]] = {}  # a set, not np.isin: ~10 us a call, for a scan of a few points
        for sp in ms:
            sensor = sp.sensor_id
            used = used_seqs.get(sensor)
            if used is None:
                used = used_seqs[sensor] = {a.seq for a in As if a.outcome in _USED and a.sensor_id == sensor}
            seqs = sp.seq.tolist()
            flags = [q in used for q in seqs] if used else [False] * len(seqs)
            by_sensor.setdefault(sensor, []).append((step, sp.t_ns, sp.t_ns if arr is None else arr, sp, flags))
    for sensor_id in sorted(by_sensor):
        rows = sorted(by_sensor[sensor_id], key=itemgetter(0, 1))  # by step, then scan time (stable)
        lens = np.array([len(r[4]) for r in rows], dtype=np.int64)
        P = world(np.concatenate([r[3].position for r in rows]).astype(np.float64, copy=False))
        used = np.fromiter(chain.from_iterable(r[4] for r in rows), dtype=bool, count=int(lens.sum()))
        rgba = np.where(used[:, None], _RGBA_USED, _RGBA_CLUTTER).astype(np.uint8)
        sink.col(f"world/meas/{sensor_id}", "points", radius=-1.75).extend(
            np.array([r[1] for r in rows], dtype=np.int64), np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[2] for r in rows], dtype=np.int64), p=Ragged(P, lens), rgba=Ragged(rgba, lens))
