"""The shipped configuration's Cartesian prefilter (`[tracker.gate] coarse_margin` of
configs/service.toml) drops no pair the fine gate keeps: on the mix scenario's sensors over 100
targets (radar and camera, their clutter and misses, radar ranges down to ~20 m), the tracker
with the shipped margin reports the same estimates, events and counts, byte for byte, as with a
prefilter fifty fine-gate radii wide. The margin only decides how many candidate pairs reach the
fine gate (the cost), never which pairs it keeps."""

from __future__ import annotations

import hashlib

import msgspec

from bench.late_data import scans, shipped_config
from fusion.tracking.tracker import Tracker


def _digest(margin: float | None) -> tuple[str, int]:
    cfg = shipped_config()
    if margin is not None:
        cfg = msgspec.structs.replace(cfg, gate=msgspec.structs.replace(cfg.gate, coarse_margin=margin))
    tr = Tracker(cfg)
    h = hashlib.sha256()
    n = 0
    for scan in scans(100, 20.0, seed=3):
        r = tr.process(scan)
        for e in r.estimates:
            h.update(repr((e.track_id, e.t_ns, e.sensor_id, e.seq, e.status, e.revision, e.nis)).encode())
            h.update(e.x.tobytes() + e.P.tobytes())
            if e.mode_probabilities is not None:
                h.update(e.mode_probabilities.tobytes())
            n += 1
        h.update(repr(r.events).encode())
    h.update(repr(sorted(tr.counts.flat().items())).encode())
    return h.hexdigest(), n


def test_the_shipped_prefilter_drops_no_pair_the_gate_keeps() -> None:
    assert shipped_config().gate.coarse_margin < 50.0
    shipped, n = _digest(None)
    assert n > 10_000
    assert shipped == _digest(50.0)[0]
