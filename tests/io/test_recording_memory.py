"""What a recording keeps between flushes is bounded by the viewed tracks' rows, not by the steps
they came from: a step's estimates are rows of its stacked arrays (every track it updated), and
the viewed tracks' estimates, kept until the next view flush, kept those whole arrays alive
(55-90 MB at 667 tracks and 10k measurements/s, the service's memory saw-tooth)."""

from __future__ import annotations

import gc
import weakref
from collections import Counter
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

from fusion.config import CartesianSensorConfig, LifecycleConfig, MotionConfig, TrackerConfig
from fusion.io.rerun_sink import RerunSink
from fusion.io.view_rows import Stacked
from fusion.tracking.detection import Detection
from fusion.tracking.results import REVIEW_ROWS
from fusion.tracking.tracker import Tracker

TARGETS = 20
SCANS = 40


def _scans(seed: int = 5):
    """TARGETS targets 200 m apart flying east at 10 m/s, one Cartesian sensor at 10 Hz."""
    rng = np.random.default_rng(seed)
    start = np.stack([np.zeros(TARGETS), 200.0 * np.arange(TARGETS)], axis=1)
    seq = 0
    for k in range(SCANS):
        t_ns = k * 100_000_000
        z = start + [10.0 * k * 0.1, 0.0] + rng.normal(0.0, 1.0, (TARGETS, 2))
        dets = []
        for zi in z:
            dets.append(Detection.of("pos", t_ns, seq, zi))
            seq += 1
        yield dets


def _tracker() -> Tracker:
    return Tracker(TrackerConfig(sensors=[CartesianSensorConfig(id="pos", std_m=[1.0, 1.0])],
                                 motion=MotionConfig(accel_psd_m2s3=0.01),
                                 lifecycle=LifecycleConfig(confirm_m=2, confirm_n=3)))


# an estimate's arrays: its own fields' and its rows of its Review block (Estimate's properties)
ARRAYS = ("x", "P", "mode_probabilities") + REVIEW_ROWS


def _stacked_arrays(e) -> list[weakref.ref]:
    """Weak references to the step's stacked arrays that e's arrays are rows of (x, P, y, S, H, ...)."""
    return [weakref.ref(a.base) for a in (getattr(e, f) for f in ARRAYS)
            if isinstance(a, np.ndarray) and a.base is not None]


def test_viewed_rows_are_arrays_of_their_own_with_the_same_values() -> None:
    """Stacked.of (what the sink keeps of the viewed rows until the view flush) shares no memory
    with the estimates' arrays (rows of their steps' stacked arrays) and holds their values."""
    tracker = _tracker()
    E = [e for dets in _scans() for e in tracker.process(dets).estimates]
    updated = [e for e in E if e.y is not None]
    assert updated and all(e.P.base is not None for e in updated), "the tracker's estimates are no views: no test"
    X, P = np.stack([e.x for e in updated]), np.stack([e.P for e in updated])
    n = len(X)
    s = Stacked.of(updated, np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64), X, P, X, X,
                   np.zeros(n, bool), np.zeros(n), X, X, conf=np.ones(n, bool), n_pos=2)
    kept = [s.prior, s.meas_pos] + [a for u in s.updates.values() for a in (u.Y, u.S, u.K)]
    for e in updated:
        for f in ARRAYS:
            a = getattr(e, f)
            if isinstance(a, np.ndarray):
                assert not any(np.shares_memory(a, k) for k in kept), f
    u = s.updates["pos"]
    assert np.array_equal(s.prior, np.stack([e.prior_x for e in updated]))
    assert np.array_equal(s.meas_pos, np.stack([e.meas_pos[:2] for e in updated]))
    assert np.array_equal(u.Y, np.stack([e.y for e in updated]))
    assert np.array_equal(u.S, np.stack([e.S for e in updated]))
    K = np.swapaxes(np.linalg.solve(np.stack([e.S for e in updated]),
                                    np.stack([e.H for e in updated]) @ np.stack([e.prior_P for e in updated])), 1, 2)
    assert np.array_equal(u.K, K)  # P- H' S^-1


def test_viewed_rows_do_not_keep_the_steps_arrays(tmp_path: Path) -> None:
    """A real sink (record flushed at every step, views only at close) fed a real tracker's steps:
    once the steps are dropped, none of their stacked arrays is alive, though the viewed tracks'
    rows wait for the view flush; the file then holds the viewed tracks' series."""
    path = tmp_path / "mem.rrd"
    sink = RerunSink(path, layout=("x", "vx", "y", "vy"), position_indices=(0, 2), velocity_indices=(1, 3),
                     flush_interval_s=1e-9, view_interval_s=1e9)
    tracker = _tracker()
    bases: list[weakref.ref] = []
    for dets in _scans():
        r = tracker.process(dets)
        bases += _stacked_arrays(r.estimates[0])
        sink.log_step(r)
        del r
    assert len(bases) >= 5 * SCANS // 2
    del tracker  # its own state and history hold the latest steps
    gc.collect()
    alive = sum(b() is not None for b in bases)
    sink.close()
    assert alive == 0, f"{alive} of {len(bases)} steps' arrays kept alive by the sink"
    rows: Counter[str] = Counter()
    for ch in RrdReader(str(path)).stream():
        if not ch.is_static:
            rows[ch.entity_path] += ch.to_record_batch().num_rows
    viewed = [k for k in rows if k.startswith("/tracks/") and k.endswith("/std")]
    assert len(viewed) == 6 and all(rows[k] >= SCANS // 2 for k in viewed)
