"""fusion.io.step_rows makes the rows its first form made (kept here as the reference, as it was
when moved out of the sink): mixed sensors in a step, steps without arrival times, every outcome,
a seq used in one step and not in another."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa

from fusion.io import step_rows
from fusion.io.columns import Column, Ragged, stack
from fusion.io.derive import world
from fusion.io.labels import short_id
from fusion.tracking.results import NO_TRACK, OUTCOME_CODE, Association, Outcome, ScanAssociations, ScanPoints

_USED = (Outcome.UPDATED,)
_SEQ_MASK = (1 << 64) - 1


def _ref_associations(steps: Sequence[Any], sink: Any) -> None:
    steps = _records(steps)
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


class _Point(NamedTuple):  # a measured point on its own, as the tracker once reported it (the reference's input)
    sensor_id: str
    t_ns: int
    seq: int
    position: np.ndarray


def _points(ms: Sequence[ScanPoints]) -> list[_Point]:
    return [_Point(sp.sensor_id, sp.t_ns, q, p) for sp in ms for q, p in zip(sp.seq.tolist(), sp.position, strict=True)]


def _ref_measured_points(steps: Sequence[Any], sink: Any) -> None:
    steps = [(_points(ms), As, step, arr) for ms, As, step, arr in _records(steps)]
    used_keys: dict[str, set[int]] = {}
    for _, As, step, _ in steps:
        for a in As:
            if a.outcome in _USED:
                used_keys.setdefault(a.sensor_id, set()).add((step << 64) | (a.seq & _SEQ_MASK))
    by_sensor: dict[str, tuple[list[int], list[Any], list[Any]]] = {}
    for ms, _, step, arr in steps:
        for m in ms:
            b = by_sensor.setdefault(m.sensor_id, ([], [], []))
            b[0].append(step)
            b[1].append(m)
            b[2].append(arr)
    for sensor_id in sorted(by_sensor):
        steps_m, ms_, arrs = by_sensor[sensor_id]
        step_m = np.array(steps_m, dtype=np.int64)
        t_m = np.fromiter((m.t_ns for m in ms_), dtype=np.int64, count=len(ms_))
        order = np.lexsort((t_m, step_m))
        keys = used_keys.get(sensor_id, set())
        used = np.fromiter(((s << 64) | (m.seq & _SEQ_MASK) in keys for s, m in zip(steps_m, ms_, strict=True)),
                           dtype=bool, count=len(ms_))[order]
        step_m, t_m = step_m[order], t_m[order]
        P = world(stack([m.position for m in ms_])[order])
        first = np.flatnonzero(np.r_[True, (step_m[1:] != step_m[:-1]) | (t_m[1:] != t_m[:-1])])
        lens = np.diff(np.r_[first, len(ms_)])
        t_r = t_m[first]
        arr_r = [arrs[i] for i in order[first].tolist()]
        arr_m = np.array([t if a is None else a for t, a in zip(t_r.tolist(), arr_r, strict=True)], dtype=np.int64)
        rgba = np.where(used[:, None], step_rows._RGBA_USED, step_rows._RGBA_CLUTTER).astype(np.uint8)
        sink.col(f"world/meas/{sensor_id}", "points", radius=-1.75).extend(
            t_r, step_m[first], arr_m, p=Ragged(P, lens), rgba=Ragged(rgba, lens))


class _Sink:
    def __init__(self) -> None:
        self.cols: dict[str, Column] = {}

    def col(self, entity: str, kind: str, **style: Any) -> Column:
        return self.cols.setdefault(entity, Column(kind, **style))


def _steps(seed: int) -> list[Any]:
    rng = np.random.default_rng(seed)
    outcomes = list(Outcome)
    out = []
    for step in range(1, 40):
        t = 1_000_000 * step
        ms, As = [], []
        sensors = ["radar1"] if step % 3 else ["radar1", "cam1", "radar1"]  # some steps mix sensors
        for k in range(int(rng.integers(0, 6))):
            s = sensors[k % len(sensors)]
            tk = t + (k % 2) * 10  # two scan times in one step now and then
            seq = int(rng.integers(0, 8))  # repeats: the same seq used in one step, not in another
            ms.append(_Point(s, tk, seq, rng.normal(size=2 if s == "radar1" else 3)))
            if rng.random() < 0.8:
                oc = outcomes[int(rng.integers(0, len(outcomes)))]
                tid = None if oc is not Outcome.UPDATED and rng.random() < 0.5 else int(rng.integers(1, 2**62))
                gated = tuple(int(g) for g in rng.integers(1, 2**62, size=int(rng.integers(0, 3))))
                As.append(Association(s, tk, seq, oc, tid, None if rng.random() < 0.3 else float(rng.random()),
                                      gated))
        out.append((_scans(ms), _blocks(As), step, None if step % 4 == 0 else t + 5))
    return out


def _blocks(As: list[Association]) -> tuple[ScanAssociations, ...]:
    """The associations of a step as the tracker reports them: one block per (sensor, time), in
    the order each first appears; as a scan does, a NIS only where the measurement updated a track."""
    groups: dict[tuple[str, int], list[Association]] = {}
    for a in As:
        groups.setdefault((a.sensor_id, a.t_ns), []).append(a)
    out = []
    for (s, t), g in groups.items():
        at = np.cumsum([0] + [len(a.gated) for a in g]).astype(np.int64)
        out.append(ScanAssociations(
            s, t, np.array([a.seq for a in g], dtype=np.int64),
            np.array([OUTCOME_CODE[a.outcome] for a in g], dtype=np.int8),
            np.array([NO_TRACK if a.track_id is None else a.track_id for a in g], dtype=np.int64),
            np.array([a.nis if a.outcome is Outcome.UPDATED and a.nis is not None else np.nan for a in g]),
            at, np.array([q for a in g for q in a.gated], dtype=np.int64)))
    return tuple(out)


def _records(steps: Sequence[Any]) -> list[Any]:
    """The steps with their associations as records, one per measurement (the reference's input)."""
    return [(ms, [a for b in Bs for a in b.rows()], step, arr) for ms, Bs, step, arr in steps]


def _scans(ms: list[_Point]) -> tuple[ScanPoints, ...]:
    """The points of a step as the tracker reports them: one ScanPoints per (sensor, time), in
    the order each first appears, its points in their order."""
    groups: dict[tuple[str, int], list[_Point]] = {}
    for p in ms:
        groups.setdefault((p.sensor_id, p.t_ns), []).append(p)
    return tuple(ScanPoints(s, t, np.array([p.seq for p in g], dtype=np.int64), np.stack([p.position for p in g]))
                 for (s, t), g in groups.items())


def _rows(c: Column) -> list[Any]:
    t, step, arr = c.times()
    fields = {}
    for k in c.names():
        if k in ("p", "rgba"):
            flat, lens = c.ragged(k, 3 if k == "p" else 4, np.float64 if k == "p" else np.uint8)
            fields[k] = (flat.tolist(), lens.tolist())
            continue
        v = c.field(k)  # as arrow holds it (what the recording gets: fusion.io.arrow_columns.components)
        fields[k] = (v if isinstance(v, pa.Array) else pa.array(v)).to_pylist()
    return [t.tolist(), step.tolist(), arr.tolist(), {k: repr(v) for k, v in fields.items()}]


def test_step_rows_equal_the_reference() -> None:
    for seed in range(5):
        steps = _steps(seed)
        new, ref = _Sink(), _Sink()
        step_rows.associations(steps, new)
        step_rows.measured_points(steps, new)
        _ref_associations(steps, ref)
        _ref_measured_points(steps, ref)
        assert sorted(new.cols) == sorted(ref.cols)
        assert any(e.startswith("world/meas/") for e in new.cols)
        for e in ref.cols:
            assert _rows(new.cols[e]) == _rows(ref.cols[e]), e
            assert new.cols[e].style == ref.cols[e].style


def test_outcomes_written_as_their_values() -> None:
    steps = _steps(1)
    sink = _Sink()
    step_rows.associations(steps, sink)
    got = pa.array(sink.cols["record/associations"].field("outcome"))
    assert got.type == pa.string()
    assert set(got.to_pylist()) <= {o.value for o in Outcome}


def _shifted(steps: list[Any], by: int) -> list[Any]:
    """The same steps with every seq moved by `by` (points and associations alike)."""
    out = []
    for ms, Bs, step, arr in steps:
        ms2 = tuple(ScanPoints(sp.sensor_id, sp.t_ns, sp.seq + by, sp.position) for sp in ms)
        Bs2 = tuple(ScanAssociations(b.sensor_id, b.t_ns, b.seq + by, b.outcome, b.track_id, b.nis, b.gated_at,
                                     b.gated) for b in Bs)
        out.append((ms2, Bs2, step, arr))
    return out


def test_measured_points_with_far_seqs_no_associations_and_another_sensors() -> None:
    """Seqs far apart (a publisher's epoch-sized counters, negative ones), steps without any
    association, and associations of a sensor with no points in the flush: the reference's rows."""
    base = _steps(3)
    lonely = _blocks([Association("lidar9", 5, 1, Outcome.UPDATED, 7, 0.5, ())])
    cases = [_shifted(base, 2**62), _shifted(base, -(2**61)), [(ms, (), step, arr) for ms, _, step, arr in base],
             [(ms, Bs + lonely, step, arr) for ms, Bs, step, arr in base]]
    for steps in cases:
        new, ref = _Sink(), _Sink()
        step_rows.measured_points(steps, new)
        _ref_measured_points(steps, ref)
        assert sorted(new.cols) == sorted(ref.cols) and new.cols
        for e in ref.cols:
            assert _rows(new.cols[e]) == _rows(ref.cols[e]), e
    used = np.concatenate([new.cols[e].ragged("rgba", 4, np.uint8)[0] for e in new.cols])
    assert (used == step_rows._RGBA_USED).all(axis=1).any()  # the case tests associated points too
