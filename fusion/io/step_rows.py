"""The rows a RerunSink makes of the steps logged since its last flush (fusion.io.rerun_sink
keeps each step's measurements and associations as they are and calls these at the flush):

- `associations`: one record/associations block of every association of those steps (its
  sensor, seq, outcome, the track's short label, the labels of the tracks it gated with, NIS);
- `measured_points`: world/meas/<sensor>, one row per step, sensor and scan time, in step then
  scan-time order, each point coloured by its association's outcome in that step (associated:
  it updated a track; else clutter).

`steps`: (measurements, associations (a ScanAssociations block per scan), step, arrival_ns or None
(then each row's t_ns)).
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
from fusion.tracking.results import NO_TRACK, OUTCOME_CODE, OUTCOMES, Outcome, ScanPoints

Step = tuple[tuple, tuple, int, int | None]
_USED = OUTCOME_CODE[Outcome.UPDATED]  # a measurement that started a track is not drawn as associated
_OUTCOME_VALUES = np.array([o.value for o in OUTCOMES], dtype=object)
_RGBA_USED = np.array(colour("associated"), dtype=np.uint8)
_RGBA_CLUTTER = np.array(colour("clutter"), dtype=np.uint8)


def associations(steps: Sequence[Step], sink: Any) -> None:
    """Every association of `steps` (their scans' ScanAssociations blocks) as one block of
    record/associations rows, in step then scan order."""
    blocks = [(b, step, arr) for _, Bs, step, arr in steps for b in Bs]
    lens = np.array([b.seq.size for b, _, _ in blocks], dtype=np.int64)
    if not lens.sum():
        return
    t = np.repeat(np.array([b.t_ns for b, _, _ in blocks], dtype=np.int64), lens)
    step_a = np.repeat(np.array([s for _, s, _ in blocks], dtype=np.int64), lens)
    arr_a = np.repeat(np.array([b.t_ns if a is None else a for b, _, a in blocks], dtype=np.int64), lens)
    sensor = np.repeat(np.array([b.sensor_id for b, _, _ in blocks], dtype=object), lens)
    track = np.concatenate([b.track_id for b, _, _ in blocks])
    # the rows' gated counts: the differences of the blocks' gated_at, less those across a block's end
    at = np.concatenate([b.gated_at for b, _, _ in blocks])
    counts = np.delete(np.diff(at), np.cumsum(lens + 1)[:-1] - 1)
    offsets = np.zeros(len(t) + 1, dtype=np.int32)
    np.cumsum(counts, out=offsets[1:])
    ids, at_id = np.unique(np.concatenate([track] + [b.gated for b, _, _ in blocks]), return_inverse=True)
    names = np.array(["" if i == NO_TRACK else short_id(i) for i in ids.tolist()], dtype=object)[at_id]
    sink.col("record/associations", "record").extend(
        t, step_a, arr_a, sensor=sensor.tolist(), seq=np.concatenate([b.seq for b, _, _ in blocks]),
        outcome=_OUTCOME_VALUES[np.concatenate([b.outcome for b, _, _ in blocks])].tolist(),
        label=names[:len(t)].tolist(),
        gated=pa.ListArray.from_arrays(pa.array(offsets), pa.array(names[len(t):], pa.string())),
        nis=np.concatenate([b.nis for b, _, _ in blocks]))  # NaN: it updated no track


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
                used = used_seqs[sensor] = {q for b in As if b.sensor_id == sensor
                                            for q, o in zip(b.seq.tolist(), b.outcome.tolist(), strict=True)
                                            if o == _USED}
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
