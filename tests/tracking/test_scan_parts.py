"""The parts a partial re-run hands run_scan, or computes for some rows only, are the whole
scan's, bit for bit: predicted positions of some rows, the lifecycle sweep given the scan's
predicted positions, and run_scan given its coarse gate (fusion.tracking.scan.Coarse)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.core.association import coarse_pairs
from fusion.tracking.history import Entry, revise
from fusion.tracking.results import Estimate
from fusion.tracking.scan import Coarse, measured_points, run_scan
from fusion.tracking.tracker import Tracker
from fusion.tracking.trackset import ROW_FIELDS
from tests.tracking.test_selective_replay import canon, mixed, shipped


@pytest.fixture(scope="module")
def state() -> tuple[Tracker, list]:
    """A tracker of the shipped configuration after 3 s of 10 targets, and the next scan."""
    dets = [x.det for x in mixed(5, n_targets=10, duration_s=3.5, spread_m=500.0)]
    keys = sorted({(d.t_ns, d.sensor_id) for d in dets})
    tr = Tracker(shipped())
    for key in keys[:-1]:
        tr.process([d for d in dets if (d.t_ns, d.sensor_id) == key])
    nxt = sorted((d for d in dets if (d.t_ns, d.sensor_id) == keys[-1]), key=lambda d: d.seq)
    return tr, nxt


def _bits(a: np.ndarray) -> bytes:
    return a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()


def test_predicted_position_of_some_rows_is_those_rows_of_the_whole(state: tuple[Tracker, list]) -> None:
    tr, nxt = state
    ts = tr.track_set
    assert len(ts) > 5
    t = nxt[0].t_ns
    pos, var = ts.predicted_position(t, 3.0)
    rows = np.array([4, 0, len(ts) - 1, 2])
    p, v = ts.predicted_position(t, 3.0, rows)
    assert _bits(p) == _bits(np.ascontiguousarray(pos[rows])) and _bits(v) == _bits(np.ascontiguousarray(var[rows]))


def test_sweep_given_the_predicted_positions_is_the_sweep(state: tuple[Tracker, list]) -> None:
    tr, nxt = state
    ts, ctx = tr.track_set, tr.ctx
    t, sm = nxt[0].t_ns, ctx.sensors[nxt[0].sensor_id]
    hit = np.zeros(len(ts), dtype=bool)
    hit[::2] = True
    # an "after" with the hit rows moved, as a scan's update moves them
    moved = ts.take(np.arange(len(ts)))
    moved.X[hit] += 1.0
    moved.t_ns[hit] = t
    a = ctx.lifecycle.sweep(ts, moved, hit, sm, t)
    b = ctx.lifecycle.sweep(ts, moved, hit, sm, t, ts.predicted_position(t, ctx.q2))
    assert canon(a) == canon(b)


def test_run_scan_given_its_coarse_gate_is_the_scan(state: tuple[Tracker, list]) -> None:
    tr, _ = state
    ctx = tr.ctx
    last = tr.history.entries[-1]  # the newest scan: its set before, its (admitted) detections
    ts, key, dets = last.before, last.key, last.dets
    mpos, mvar = measured_points(ctx.sensors[key[1]], dets)
    ci, cj = coarse_pairs(*ts.predicted_position(key[0], ctx.q2), mpos, mvar, k=ctx.coarse_k)
    assert ci.size > 0
    whole = run_scan(ts, key, dets, ctx)
    given = run_scan(ts, key, dets, ctx, Coarse(ci, cj, mpos, mvar))
    for f in ("estimates", "events", "associations", "tally", "positions", "variances", "coarse"):
        assert canon(getattr(whole, f)) == canon(getattr(given, f)), f
    for f in ROW_FIELDS:
        a, b = getattr(whole.after, f), getattr(given.after, f)
        assert (a is None) == (b is None) and (a is None or _bits(a) == _bits(b)), f
    assert whole.estimates


def _est(tid: int, x: float) -> Estimate:
    return Estimate(tid, 5, "s", 1, np.array([x]), np.eye(1), "confirmed", 0, None)


def test_revise_keeps_the_stored_estimates_of_kept_tracks_and_retracts_the_others() -> None:
    prev = Entry((5, "s"), (), None)  # type: ignore[arg-type]
    revise(prev, None, [_est(1, 1.0), _est(2, 2.0), _est(3, 3.0)])
    entry = Entry((5, "s"), (), None)  # type: ignore[arg-type]
    out = revise(entry, prev, [_est(1, 1.5)], kept=np.array([2, 7]))
    assert [(e.track_id, e.revision, e.status) for e in out] == [(1, 1, "confirmed"), (3, 1, "retracted")]
    assert entry.emitted[2] == prev.emitted[2]
    assert entry.emitted[3][0] == 1 and not entry.emitted[3][2]
    assert 7 not in entry.emitted
