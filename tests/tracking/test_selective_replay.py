"""Selective replay (fusion.tracking.replay) is bit-identical to replaying every scan whole.

The same arrival sequence goes to a tracker that replays selectively (the default) and to one
that replays every scan whole (selective_replay=False). Every StepResult (estimates, events,
associations, measured points, replays: arrays compared by their bytes), the final track set
(every column, bit for bit) and the counts must be equal, on adversarial late data:
  - shipped configuration (IMM cv+ct, radar + camera): targets crossing, clutter, a turn,
    random per-detection delays inside the window, random batches;
  - late births: a target's first detections all arrive late;
  - neighbours: targets passing close, their detections held back so that the late ones change
    which track takes which measurement;
  - deletions: targets that vanish (tracks deleted) and late data that arrive around it;
  - capacity: max_tracks small enough that births are refused (the scan is then run whole).
Each case also checks that the selective path ran (partial re-runs happened) where it can.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import msgspec
import numpy as np
import pytest

import fusion.tracking.tracker as tracker_module
from fusion.config import TrackerConfig, load_service_config
from fusion.tracking.detection import Detection
from fusion.tracking.results import REVIEW_ROWS, Estimate
from fusion.tracking.tracker import Tracker
from fusion.tracking.trackset import ROW_FIELDS, Rows, TrackSet
from tests.tracking.streams import CLUTTER, Labeled, Sensor, constant_velocity, detect, in_order

ROOT = Path(__file__).resolve().parents[2]
RADAR = Sensor("radar1", "radar", period_s=0.1, range_std_m=5.0, bearing_std_rad=0.003, position_m=(500.0, -800.0))
CAM = Sensor("cam1", "cartesian", period_s=0.2, offset_s=0.05, std_m=3.0)


def shipped(**lifecycle: int) -> TrackerConfig:
    cfg = load_service_config(ROOT / "configs" / "service.toml").tracker
    if lifecycle:
        cfg = msgspec.structs.replace(cfg, lifecycle=msgspec.structs.replace(cfg.lifecycle, **lifecycle))
    return cfg


# what an estimate says: its fields, with its rows of its Review block (Estimate's properties of the same names)
ESTIMATE_FIELDS = tuple(f for f in Estimate.__struct_fields__ if f not in ("review", "row")) + REVIEW_ROWS


def canon(x: object) -> object:
    """A comparable form: arrays as (dtype, shape, bytes), dataclasses and Structs field by field."""
    if isinstance(x, np.ndarray):
        return (x.dtype.str, x.shape, x.tobytes())
    if isinstance(x, Estimate):  # its review rows, not the blocks they are rows of (a partial re-run's are smaller)
        return ("Estimate", tuple(canon(getattr(x, f)) for f in ESTIMATE_FIELDS))
    if isinstance(x, msgspec.Struct):
        return (type(x).__name__, tuple(canon(getattr(x, f)) for f in x.__struct_fields__))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__, tuple(canon(getattr(x, f.name)) for f in dataclasses.fields(x)))
    if isinstance(x, list | tuple):
        return tuple(canon(v) for v in x)
    if isinstance(x, dict):
        return tuple(sorted((k, canon(v)) for k, v in x.items()))
    return x


def arrivals(dets: list[Labeled], rng: np.random.Generator, *, late_fraction: float, max_back: int,
             hold: set[int] | None = None) -> list[list]:
    """Scans in order, with some detections held back 1..max_back scans (`hold`: indices into
    dets always held back); then batches of random sizes."""
    by_scan: dict[tuple[int, str], list[int]] = {}
    for i, d in enumerate(dets):
        by_scan.setdefault((d.det.t_ns, d.det.sensor_id), []).append(i)
    keys = sorted(by_scan)
    due: dict[int, list[int]] = {}
    calls: list[list] = []
    for k, key in enumerate(keys):
        now = []
        for i in by_scan[key]:
            if (hold is not None and i in hold) or rng.random() < late_fraction:
                due.setdefault(k + int(rng.integers(1, max_back + 1)), []).append(i)
            else:
                now.append(i)
        now += due.pop(k, [])
        rng.shuffle(now)
        while now:
            n = int(rng.integers(1, len(now) + 1))
            calls.append([dets[i].det for i in now[:n]])
            now = now[n:]
    rest = [dets[i].det for k in sorted(due) for i in due[k]]
    if rest:
        calls.append(rest)
    return calls


def compare(cfg: TrackerConfig, calls: list[list], monkeypatch: pytest.MonkeyPatch) -> dict[str, int]:
    """Run both trackers on `calls`; assert equality; return how the selective one replayed."""
    stats = {"partial": 0, "whole": 0, "rerun_tracks": 0, "tracks": 0}
    real = tracker_module.rerun

    def counting(ts, *args, **kw):  # type: ignore[no-untyped-def]
        p = real(ts, *args, **kw)
        stats["partial" if p is not None else "whole"] += 1
        if p is not None:
            stats["rerun_tracks"] += p.rerun_tracks
            stats["tracks"] += len(ts)
        return p

    monkeypatch.setattr(tracker_module, "rerun", counting)
    sel, full = Tracker(cfg), Tracker(cfg, selective_replay=False)
    for n, batch in enumerate(calls):
        a, b = sel.process(batch), full.process(batch)
        assert canon(a) == canon(b), f"call {n}: the step results differ"
    for f in ROW_FIELDS:
        x, y = getattr(sel.track_set, f), getattr(full.track_set, f)
        assert (x is None) == (y is None)
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), f
    assert sel.counts == full.counts
    assert canon(sel.predict(sel.now_ns)) == canon(full.predict(full.now_ns))  # type: ignore[arg-type]
    assert sel.counts.replays > 0
    return stats


def mixed(seed: int, *, n_targets: int, duration_s: float, **kw: object) -> list[Labeled]:
    rng = np.random.default_rng(seed)
    truth = constant_velocity(n_targets=n_targets, duration_s=duration_s, rng=rng, **kw)  # type: ignore[arg-type]
    parts = [detect(truth, s, rng=rng, pd=0.9, clutter_mean=1.0, region_m=(-800, 800, -800, 800))
             for s in (RADAR, CAM)]
    return in_order(*parts)


@pytest.mark.parametrize("seed", [1, 2])
def test_shipped_configuration_random_late_data(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    dets = mixed(seed, n_targets=12, duration_s=6.0, spread_m=600.0, manoeuvre=(0, 2.0, 4.0, 0.2))
    calls = arrivals(dets, np.random.default_rng(seed + 100), late_fraction=0.1, max_back=15)
    st = compare(shipped(), calls, monkeypatch)
    assert st["partial"] > 20 and st["rerun_tracks"] < st["tracks"] / 2, st


def test_late_births(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every detection of targets 0 and 1 during their first second arrives late."""
    dets = mixed(3, n_targets=6, duration_s=5.0, spread_m=500.0)
    first = min(d.det.t_ns for d in dets)
    hold = {i for i, d in enumerate(dets) if d.origin in (0, 1) and d.det.t_ns < first + 1_000_000_000}
    calls = arrivals(dets, np.random.default_rng(4), late_fraction=0.05, max_back=12, hold=hold)
    st = compare(shipped(), calls, monkeypatch)
    assert st["partial"] > 0, st


def test_late_detections_that_change_neighbours_associations(monkeypatch: pytest.MonkeyPatch) -> None:
    """Crossing targets (1 s of travel apart at the crossing), most of their detections near the
    crossing late: which track takes which measurement changes when they arrive."""
    dets = mixed(5, n_targets=5, duration_s=8.0, crossing=True)
    near = {i for i, d in enumerate(dets) if d.origin != CLUTTER and 3.0e9 <= d.det.t_ns <= 5.0e9
            and (d.det.seq % 3) != 0}
    calls = arrivals(dets, np.random.default_rng(6), late_fraction=0.1, max_back=15, hold=near)
    st = compare(shipped(), calls, monkeypatch)
    assert st["partial"] > 0, st


def test_deletions_around_late_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """Targets vanish (their tracks coast and are deleted, coast_s 0.5 s) while late data arrive."""
    rng = np.random.default_rng(7)
    life = [(0.0, 2.5), (0.0, 3.0), (1.0, 6.0), (0.0, 6.0), (0.5, 4.0), (0.0, 6.0)]
    truth = constant_velocity(n_targets=6, duration_s=6.0, rng=rng, spread_m=500.0, lifetimes_s=life)
    dets = in_order(*[detect(truth, s, rng=rng, pd=0.85, clutter_mean=1.5, region_m=(-700, 700, -700, 700))
                      for s in (RADAR, CAM)])
    calls = arrivals(dets, np.random.default_rng(8), late_fraction=0.15, max_back=15)
    cfg = shipped(confirm_m=3, confirm_n=5)
    cfg = msgspec.structs.replace(cfg, lifecycle=msgspec.structs.replace(cfg.lifecycle, coast_s=0.5))
    full = Tracker(cfg, selective_replay=False)
    for b in calls:
        full.process(b)
    assert full.counts.deletions, "the case must delete tracks"
    st = compare(cfg, calls, monkeypatch)
    assert st["partial"] > 0, st


def test_capacity_runs_the_whole_scan(monkeypatch: pytest.MonkeyPatch) -> None:
    """max_tracks below what the data would start: births are refused for capacity, and those
    scans are run whole (their counts are global); the result is still the full replay's."""
    dets = mixed(9, n_targets=8, duration_s=4.0, spread_m=500.0)
    calls = arrivals(dets, np.random.default_rng(10), late_fraction=0.15, max_back=10)
    st = compare(shipped(max_tracks=6), calls, monkeypatch)
    full = Tracker(shipped(max_tracks=6), selective_replay=False)
    for b in calls:
        full.process(b)
    assert full.counts.births_refused_capacity > 0
    assert st["whole"] > 0, st


def test_changed_since_compares_bits_and_follows_ids() -> None:
    """A row is unchanged only if the same track's row is identical bit for bit (-0.0 is not
    0.0); rows are matched by id, not position; `among` limits the rows compared."""
    tr = Tracker(shipped())
    dets = mixed(11, n_targets=4, duration_s=1.0, spread_m=300.0)
    for d in dets:
        tr.process([d.det])
    ts = tr.track_set
    n = len(ts)
    assert n >= 3
    assert not ts.changed_since(ts).any()
    flipped = ts.take(np.arange(n)[::-1])  # the same rows in another order
    assert not flipped.changed_since(ts).any()
    other = ts.take(np.arange(n))
    other.X[1, 0] = -other.X[1, 0] if other.X[1, 0] != 0 else -0.0
    assert other.changed_since(ts).tolist() == [i == 1 for i in range(n)]
    assert not other.changed_since(ts, among=ts.ids[[0, 2]]).any()  # row 1 not among those compared
    assert other.changed_since(ts, among=ts.ids[[1]]).tolist() == [i == 1 for i in range(n)]
    fewer = ts.take(np.arange(1, n))
    assert ts.changed_since(fewer).tolist() == [i == 0 for i in range(n)]  # a track the old set lacks


@pytest.mark.parametrize("n", [5, 40], ids=["few-rows", "many-rows"])
def test_changed_since_finds_one_bit_in_any_column(n: int) -> None:
    """n random rows of the shipped layout (few: compared one by one; many: in a compiled call);
    one bit flipped in one row of one column at a time is that row changed, and no other (a
    bool flipped as a value); -0.0 against 0.0 is a change, the same NaN is not; the same rows
    in another order are unchanged, and `among` limits what is compared."""
    layout = Tracker(shipped()).track_set.layout
    rng = np.random.default_rng(n)
    empty = Rows.empty(layout)
    cols = {}
    for f in ROW_FIELDS:
        e = getattr(empty, f)
        if e is not None:
            shape = (n, *e.shape[1:])
            cols[f] = (rng.random(shape) < 0.5 if e.dtype == bool else rng.standard_normal(shape)
                       if e.dtype.kind == "f" else rng.integers(0, 100, shape).astype(e.dtype))
    cols["ids"] = rng.choice(2**62, n, replace=False).astype(np.int64)
    cols["X"][:, 0] = 0.0
    cols["P"][:, 0, 0] = np.nan
    base = TrackSet(Rows(**{f: cols.get(f) for f in ROW_FIELDS}), layout)
    assert not base.changed_since(base.take(np.arange(n)[::-1])).any()
    copy = TrackSet(Rows(**{f: None if f not in cols else cols[f].copy() for f in ROW_FIELDS}), layout)
    assert not copy.changed_since(base).any()  # the same bits (the NaNs too) in other arrays
    for f in [f for f in cols if f != "ids"]:
        r = int(rng.integers(n))
        mod = {g: c.copy() for g, c in cols.items()}
        if mod[f].dtype == bool:
            mod[f][r].flat[0] = not mod[f][r].flat[0]
        else:
            flat = mod[f][r:r + 1].view(np.uint8).reshape(-1)
            flat[int(rng.integers(flat.size))] ^= np.uint8(1 << int(rng.integers(8)))
        ts = TrackSet(Rows(**{g: mod.get(g) for g in ROW_FIELDS}), layout)
        assert ts.changed_since(base).tolist() == [i == r for i in range(n)], f
        others = np.delete(cols["ids"], r)
        assert not ts.changed_since(base, among=others).any(), f
    neg = {g: c.copy() for g, c in cols.items()}
    neg["X"][n - 1, 0] = -0.0
    ts = TrackSet(Rows(**{g: neg.get(g) for g in ROW_FIELDS}), layout)
    assert ts.changed_since(base).tolist() == [i == n - 1 for i in range(n)]


def test_a_restarted_sensor_then_late_data(monkeypatch: pytest.MonkeyPatch) -> None:
    """A sensor's two epochs send the same seqs at the same times (a restarted publisher): a scan
    holds equal seqs, and the tracks they start share ids (an id is the sensor, seq and time).
    Late detections then join those scans, one of them with a seq both epochs used. (A first
    version of rerun_sets, which took track ids for unique, reached one row of such an id and
    differed from the whole replay here.)"""
    from tests.service.test_nothing_lost import WIDE
    from tests.tracking.helpers import make_tracker
    from tests.tracking.test_refusals import CART, S

    rng = np.random.default_rng(3)

    def burst(epoch: int, x0: float) -> list[Detection]:
        return [Detection.of("cart", S + k * S // 2, k, [x0 + rng.normal(0, 1.0), 0.0], epoch=epoch) for k in range(6)]

    calls: list[list] = [burst(1000, 0.0) + burst(2000, 50.0)]
    calls.append([Detection.of("cart", S + 2 * S // 2, 99, [25.0, 0.0], epoch=1000)])
    calls.append([Detection.of("cart", S + S // 2, 0, [1.0, 3.0], epoch=3000)])
    calls += [[Detection.of("cart", S + k * S // 2, k, [rng.normal(0, 1.0), 0.0], epoch=1000)] for k in range(6, 10)]
    st = compare(make_tracker([CART], time=WIDE).config, calls, monkeypatch)
    assert st["partial"] + st["whole"] >= 6, st  # the late ones re-ran the scans after them


def test_a_scan_holding_a_seq_twice_runs_again_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    """Twelve targets 1-6 km apart seen by one sensor (epoch 1000, seq = target); at every scan a
    restarted publisher (epoch 2000) sends seqs 0-5 again at the same times, at other targets'
    places; scan 4's seq 0 arrives after the last scan, and the scans from it run again: whole,
    since each holds a seq twice (a partial re-run, its pairs keyed by seq, differed from the
    whole one there)."""
    from itertools import groupby

    from tests.service.test_nothing_lost import WIDE
    from tests.tracking.helpers import make_tracker
    from tests.tracking.test_order_invariance import two_epochs
    from tests.tracking.test_refusals import CART

    calls = [list(scan) for _, scan in groupby(two_epochs(), key=lambda d: d.t_ns)]
    held = [calls[4].pop(0)]
    calls.append(held)
    st = compare(make_tracker([CART], time=WIDE).config, calls, monkeypatch)
    assert st["whole"] >= 10 and st["partial"] == 0, st
