"""The tracks with views of their own are a function of the data, not of arrival order: the first
MAX_VIEWED by (sensor time of their first confirmed estimate, track id) (fusion.io.viewed), with
their time series from that first confirmed row on."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from fusion.io.inspect_read import RunRecord
from fusion.io.labels import short_id
from fusion.io.rrd_read import read_chunks
from fusion.io.track_rows import MAX_VIEWED
from fusion.io.viewed import FINAL, ViewedTracks
from fusion.tracking.results import Estimate
from tests.io.scenario_run import record_scenario


def _est(track: int, t: int, status: str = "confirmed", revision: int = 0, sensor: str = "s") -> Estimate:
    return Estimate(track, t, sensor, 0, np.zeros(2), np.eye(2), status, revision, None)


def test_a_late_confirmation_before_the_horizon_takes_its_place() -> None:
    v = ViewedTracks(2)
    v.note([_est(3, 50), _est(1, 60)])
    v.settle(40)  # both could still be preceded: nothing chosen
    assert v.labels == {} and v.candidates() == {1, 3}
    v.note([_est(2, 45)])  # late data confirm track 2, earlier than both
    v.settle(55)
    assert list(v.labels) == [2, 3] and not v.open and v.candidates() == set()
    v.note([_est(9, 1)])  # once settled, nothing more is noted
    assert list(v.labels) == [2, 3] and 9 not in v.kept_ids() and v.kept_ids() == [2, 3]


def test_revisions_and_retractions_move_a_candidate() -> None:
    v = ViewedTracks(3)
    v.note([_est(5, 10), _est(5, 20), _est(6, 15)])
    v.note([_est(5, 10, "tentative", revision=1)])  # a replay: track 5 not confirmed at t = 10 after all
    v.note([_est(7, 12), _est(7, 12, "retracted", revision=1)])  # track 7's only confirmed row withdrawn
    v.settle(FINAL)
    assert list(v.labels) == [6, 5]  # 6 first confirmed at 15, 5 at 20; 7 never
    assert v.labels[6] == short_id(6)


def test_ties_go_by_track_id_and_the_horizon_is_exclusive() -> None:
    v = ViewedTracks(6)
    v.note([_est(8, 100), _est(4, 100)])
    v.settle(100)  # first confirmed at 100: still open to a row at 100
    assert v.labels == {}
    v.settle(101)
    assert list(v.labels) == [4, 8]


def _viewed(path: Path) -> set[str]:
    return {m.group(1) for ch in RrdReader(str(path)).stream()
            if (m := re.match(r"/tracks/([^/]+)/", ch.entity_path))}


def _first_rows(path: Path) -> dict[str, int]:
    """The first t of each viewed track's position series."""
    out: dict[str, int] = {}
    for ch in RrdReader(str(path)).stream():
        m = re.match(r"/tracks/([^/]+)/position/x/estimate$", ch.entity_path)
        b = ch.to_record_batch()
        if m and "t" in b.schema.names and b.num_rows:  # (the style is a static chunk: no times)
            t = int(b.column("t").cast("int64").to_numpy().min())
            out[m.group(1)] = min(out.get(m.group(1), t), t)
    return out


def _expected(path: Path) -> tuple[list[str], dict[str, int]]:
    """From the file's record (record/estimates, latest revisions): the first MAX_VIEWED tracks
    by (first confirmed t, id), and their first confirmed t."""
    run = RunRecord()
    run.add(read_chunks(path)[0])
    first: dict[int, int] = {}
    for i in run.latest():
        if run.est["status"][i] == "confirmed":
            k, t = int(run.est["track"][i]), int(run.est["t"][i])
            first[k] = min(first.get(k, t), t)
    chosen = sorted(first, key=lambda k: (first[k], k))[:MAX_VIEWED]
    return [short_id(k) for k in chosen], {short_id(k): first[k] for k in chosen}


@pytest.mark.parametrize("view_interval_s", [None, 0.0], ids=["default-flushes", "a-view-flush-per-300-rows"])
def test_the_viewed_tracks_are_the_same_whatever_the_arrival_order(view_interval_s: float | None,
                                                                    tmp_path: Path) -> None:
    """mix (6 targets, clutter, radar + camera) in time order and in three shuffled orders (more
    late arrivals, replays): the same viewed tracks, those the data say (before fusion.io.viewed,
    the four runs viewed four different sets), each from its first confirmed row on, also when
    the candidates' rows are held across many view flushes."""
    got = {}
    for seed in (None, 1, 2, 3):
        p = tmp_path / f"mix-{seed}.rrd"
        if view_interval_s is None:
            record_scenario("mix", p, duration_s=30.0, shuffle_seed=seed)
        else:
            record_scenario("mix", p, duration_s=30.0, shuffle_seed=seed, flush_rows=300, flush_interval_s=1e9,
                            view_interval_s=view_interval_s)
        got[seed] = _viewed(p)
        labels, first = _expected(p)
        assert got[seed] == set(labels), seed
        assert _first_rows(p) == first, seed
    assert len({frozenset(v) for v in got.values()}) == 1, got
