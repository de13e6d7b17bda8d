"""Bounded memory on long streams: the replay history and the seen-set stay inside the window,
and the number of tracks inside max_tracks (births refused and counted when full)."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import LifecycleConfig, TimeConfig
from tests.tracking.helpers import make_tracker
from tests.tracking.streams import Sensor, circling_scans

CART = Sensor("cart", "cartesian", std_m=1.0)
PERIOD_S = 0.1
LAG_S = 1.0
N_TARGETS = 10


def run_long(n_detections: int, *, seed: int, time: TimeConfig, lifecycle: LifecycleConfig | None = None):
    tr = make_tracker([CART], time=time, lifecycle=lifecycle)
    stream = circling_scans(n_targets=N_TARGETS, n_scans=10**9, rng=np.random.default_rng(seed),
                            period_s=PERIOD_S, clutter_mean=1.0)
    peak = {"history": 0, "seen": 0, "tracks": 0, "scan": 0}
    outcomes: dict[str, int] = {}
    window: list[int] = []  # detections per scan over the last scans, for the seen bound
    while tr.counts.received < n_detections:
        batch = next(stream)
        result = tr.process(batch)
        for a in result.each_association():
            outcomes[a.outcome] = outcomes.get(a.outcome, 0) + 1
        window = (window + [len(batch)])[-(round(LAG_S / PERIOD_S) + 1):]
        assert tr.intake.seen_len <= sum(window)
        peak["history"] = max(peak["history"], len(tr.history))
        peak["seen"] = max(peak["seen"], tr.intake.seen_len)
        peak["tracks"] = max(peak["tracks"], len(tr.tracks))
        peak["scan"] = max(peak["scan"], len(batch))
    return tr, peak, outcomes


def check_bounded(n_detections: int, seed: int) -> None:
    tr, peak, _ = run_long(n_detections, seed=seed, time=TimeConfig(lag_s=LAG_S))
    scans_in_window = round(LAG_S / PERIOD_S) + 1  # scans with t in [newest - lag, newest]
    assert peak["history"] == scans_in_window, peak
    assert peak["seen"] <= scans_in_window * peak["scan"], peak
    assert peak["tracks"] <= 3 * N_TARGETS, peak  # the targets plus short-lived clutter tracks
    assert len(tr.confirmed()) >= N_TARGETS - 2
    assert tr.counts.received == tr.counts.applied >= n_detections


@pytest.mark.parametrize("seed", [31], ids=["seed31"])
def test_long_stream_keeps_history_and_seen_bounded(seed: int) -> None:
    check_bounded(20_000, seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [32], ids=["seed32"])
def test_million_detections_keep_history_and_seen_bounded(seed: int) -> None:
    check_bounded(1_000_000, seed)


def test_max_lag_scans_caps_the_history() -> None:
    _tr, peak, _ = run_long(3_000, seed=33, time=TimeConfig(lag_s=LAG_S, max_lag_scans=4))
    assert peak["history"] == 4


def test_full_tracker_refuses_births_and_counts_them() -> None:
    lc = LifecycleConfig(max_tracks=5)
    tr, peak, outcomes = run_long(3_000, seed=34, time=TimeConfig(lag_s=LAG_S), lifecycle=lc)
    assert peak["tracks"] == 5
    refused = tr.counts.births_refused_capacity
    assert refused > 0
    assert outcomes.get("capacity", 0) == refused
    assert outcomes.get("updated", 0) > 0
