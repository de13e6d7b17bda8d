"""`fusion inspect` on several recordings: independent runs told apart by their run id and averaged
(Bar-Shalom's N-run test), a rotated set merged as one run, and figures that are a function of the
data only (the same for the same data arriving in another order), OSPA/GOSPA included. Real .rrd
files written and read back."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fusion.core.metrics import gospa, ospa
from fusion.io.derive import OSPA_C_M
from fusion.io.inspect import format_summary, summarise
from fusion.io.inspect_read import file_meta
from fusion.io.recording import RotatingSink
from fusion.io.rrd_read import read_chunks
from tests.io.scenario_run import latest, maneuver_run, record_maneuver, record_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def three_runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("runs")
    for seed in (3, 4, 5):
        record_maneuver(d / f"seed{seed}.rrd", seed=seed)
    return d


def test_independent_runs_are_told_apart_and_averaged(three_runs: Path) -> None:
    files = sorted(three_runs.glob("*.rrd"))
    ids = [file_meta(read_chunks(p)[0])["run_id"] for p in files]
    assert len(set(ids)) == 3
    s = summarise(three_runs)
    singles = [summarise(p) for p in files]
    assert s.runs == 3 and s.run_ids == ids
    assert [t.run for t in s.tracks] == [r for r, one in enumerate(singles, start=1) for _ in one.tracks]
    assert s.nees.samples == sum(x.nees.samples for x in singles)
    assert s.nees.mean == pytest.approx(sum(x.nees.mean * x.nees.samples for x in singles) / s.nees.samples, rel=1e-12)
    assert s.nees.runs == 3 and "3 independent runs" in s.nees.assumes
    pt = s.nees.per_time
    assert pt is not None and pt.runs == 3 and 0 < pt.inside <= pt.times <= 200
    text = format_summary(s)
    assert "runs: 3 (told apart by the run id each recording carries" in text
    assert "averaged over the 3 runs at each time held by all of them" in text
    lines = text.splitlines()
    assert lines[lines.index(next(x for x in lines if x.startswith("tracks: "))) + 1].split()[:2] == ["run", "track"]
    one = summarise(three_runs, runs_by="one")  # meant for e.g. a service restarted from a checkpoint
    assert one.runs == 1 and one.nees.per_time is None
    assert summarise(files, runs_by="files").runs == 3


def test_a_rotated_set_is_one_run(tmp_path: Path, three_runs: Path) -> None:
    tr, _, _ = maneuver_run()
    sink = RotatingSink(tmp_path, prefix="rot", layout=tr.layout, position_indices=tr.position_indices,
                        velocity_indices=tr.velocity_indices, rotate_bytes=150_000, rotate_s=1e9, flush_interval_s=0.0)
    record_maneuver(None, sink=sink)
    assert len(sink.files) >= 3, "no rotation happened"
    assert len({file_meta(read_chunks(p)[0])["run_id"] for p in sink.files}) == 1
    s = summarise(sink.files)
    whole = summarise(three_runs / "seed3.rrd")  # the same run (seed 3) in one file
    assert s.runs == 1 and s.nees.per_time is None
    assert [t.estimates for t in s.tracks] == [t.estimates for t in whole.tracks]
    assert (s.nees.mean, s.nis.mean, s.ospa_m) == pytest.approx((whole.nees.mean, whole.nis.mean, whole.ospa_m),
                                                                rel=1e-12)
    assert summarise([*sink.files, three_runs / "seed4.rrd"]).runs == 2


def test_ospa_and_gospa_are_computed_from_the_latest_revisions(three_runs: Path) -> None:
    results, truth = record_maneuver(None, sink=_NullSink())
    est = latest(results)
    d_o, d_g = [], []
    scans = sorted({a.t_ns for r in results for a in r.associations})
    for t in scans:
        pts = [e.x[[0, 2]] for k, e in sorted(est.items()) if k[1] == t and e.status == "confirmed"]
        X = np.array(pts).reshape(-1, 2)
        d_o.append(ospa(X, truth[t][None, [0, 2]], c=OSPA_C_M))
        d_g.append(gospa(truth[t][None, [0, 2]], X, c=OSPA_C_M))
    s = summarise(three_runs / "seed3.rrd")
    assert s.ospa_times == len(scans)
    assert s.ospa_m == pytest.approx(float(np.mean(d_o)), rel=1e-12)
    assert s.gospa_m == pytest.approx(float(np.mean(d_g)), rel=1e-12)


def test_the_same_data_in_another_arrival_order_gives_the_same_figures(tmp_path: Path) -> None:
    # a record flush after every ingest: a flush between the truths of one time (the worst case of
    # the wall-clock cadence, which made this test fail now and then) scores the same
    record_scenario("mix", tmp_path / "a.rrd", duration_s=8.0, flush_interval_s=0.0)
    record_scenario("mix", tmp_path / "b.rrd", duration_s=8.0, batch=7, shuffle_seed=1, flush_interval_s=0.0)
    a, b = summarise(tmp_path / "a.rrd"), summarise(tmp_path / "b.rrd")
    assert b.events["replay"] > 3 * a.events.get("replay", 0), "the orders hardly differ: the case is not exercised"
    assert a.ospa_m is not None and a.ospa_times > 0 and len(a.tracks) >= 4
    for field_ in ("tracks", "position_rmse", "nis", "nees", "ospa_m", "gospa_m", "ospa_times", "sensors",
                   "tentative_only", "events_net"):
        assert getattr(a, field_) == getattr(b, field_), field_
    arrival = ("counts: ", "replays: ")  # what the arrival order did, said as such
    lines = [[x for x in format_summary(s).splitlines()[1:] if not x.startswith(arrival)] for s in (a, b)]
    assert lines[0] == lines[1]


def test_inspect_cli_runs(three_runs: Path) -> None:
    def run(*extra: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "fusion", "inspect", str(three_runs), *extra],
                              capture_output=True, text=True, timeout=120, cwd=ROOT)

    out = run("--json", "--runs", "one")
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["runs"] == 1
    text = run()
    assert text.returncode == 0 and "runs: 3 (told apart by the run id" in text.stdout, text.stdout + text.stderr
    bad = run("--runs", "seeds")
    assert bad.returncode != 0 and "--runs" in bad.stderr


class _NullSink:
    """Takes a run's steps and writes nothing (to get the results of record_maneuver's run)."""

    def log_truths(self, truths: object) -> None:
        pass

    def log_step(self, result: object) -> None:
        pass

    def close(self) -> None:
        pass


def test_set_distance_series_against_stone_soup() -> None:
    """Per scan time, the last row of each track against the truth: GOSPA equal to Stone Soup's;
    OSPA equal to Stone Soup's at p = 1 (Stone Soup 1.9 assigns on the cut distances d_c, not on
    d_c^p, so at p = 2 its OSPA is at or above the definition's minimum, which fusion finds)."""
    ss = pytest.importorskip("stonesoup.metricgenerator.ospametric")
    import datetime

    from stonesoup.measures import Euclidean
    from stonesoup.types.state import State

    from fusion.io.derive import set_distance_series

    rng = np.random.default_rng(21)
    times = np.arange(1, 31, dtype=np.int64) * 10**8
    truth = {int(t): rng.normal(scale=8.0, size=(int(rng.integers(1, 6)), 3)) for t in times[::2]}  # half with truth
    t_rows, tracks, W = [], [], []
    for t in times.tolist():
        for track in rng.choice(8, size=int(rng.integers(0, 6)), replace=False).tolist():
            for _ in range(int(rng.integers(1, 3))):  # a track updated twice at t (two sensors): the last counts
                t_rows.append(t)
                tracks.append(track)
                W.append(rng.normal(scale=8.0, size=3))
    t_a, tr_a, W_a = np.array(t_rows), np.array(tracks), np.array(W)
    o, g = set_distance_series(t_a, tr_a, W_a, truth, times, max_points=300)
    assert o.size == g.size == len(truth)
    stamp = datetime.datetime(2020, 1, 1)
    states = lambda A: [State(a[:, None], timestamp=stamp) for a in A]  # noqa: E731
    gm = ss.GOSPAMetric(c=OSPA_C_M, p=2, measure=Euclidean())
    om = ss.OSPAMetric(c=OSPA_C_M, p=2, measure=Euclidean())
    om1 = ss.OSPAMetric(c=OSPA_C_M, p=1, measure=Euclidean())
    for k, t in enumerate(sorted(truth)):
        rows = np.flatnonzero(t_a == t)
        last = {int(tr_a[i]): int(i) for i in rows}
        E = W_a[sorted(last.values())] if last else np.empty((0, 3))
        T = truth[t]
        assert g[k] == pytest.approx(gm.compute_gospa_metric(states(E), states(T))[0].value["distance"], rel=1e-12)
        assert ospa(T, E, c=OSPA_C_M, p=1) == pytest.approx(om1.compute_OSPA_distance(states(E), states(T)).value,
                                                            rel=1e-12)
        assert o[k] <= om.compute_OSPA_distance(states(E), states(T)).value + 1e-12
        assert o[k] == pytest.approx(ospa(T, E, c=OSPA_C_M), rel=1e-12)
