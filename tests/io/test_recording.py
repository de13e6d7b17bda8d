"""Recordings: every step in the .rrd, read back with rerun's reader; inspect; rotation; crashes."""

from __future__ import annotations

import json
import subprocess
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from fusion.io.derive import ellipse_points
from fusion.io.inspect import summarise
from fusion.io.labels import short_id
from fusion.io.recording import RotatingSink
from tests.io.scenario_run import latest, maneuver_run, record_maneuver


def _rows(path: Path) -> dict[str, int]:
    rows: Counter[str] = Counter()
    for ch in RrdReader(str(path)).stream():
        if not ch.is_static:  # series names are static rows of their own
            rows[ch.entity_path] += ch.to_record_batch().num_rows
    return dict(rows)


def _record(path: Path, *, batch: int = 1) -> tuple[list, dict]:
    return record_maneuver(path, batch=batch)


@pytest.fixture(scope="module")
def rerun_cli() -> Path:
    """The real rerun binary (not the Python wrapper, which leaves servers behind when killed)."""
    import rerun_cli as pkg

    exe = Path(pkg.__file__).parent / "rerun"
    assert exe.exists(), f"rerun CLI not found at {exe}"
    return exe


def test_every_estimate_is_in_the_recording(tmp_path: Path, rerun_cli: Path) -> None:
    path = tmp_path / "run.rrd"
    results, truth = _record(path)
    rows = _rows(path)
    per_track = Counter(e.track_id for r in results for e in r.estimates if e.status == "confirmed")
    tentative = sum(1 for r in results for e in r.estimates if e.status == "tentative")
    assert per_track and tentative, "the tracker produced no estimates"
    assert rows["/world/tentative"] == tentative
    assert rows["/world/estimates"] == sum(per_track.values())
    assert rows["/record/estimates"] == sum(len(r.estimates) for r in results)  # retractions too
    for tid, n in per_track.items():  # one target: every confirmed track has views of its own
        lab = short_id(tid)
        assert rows[f"/world/tracks/{lab}/now"] == n
        assert rows[f"/world/tracks/{lab}/cov"] == n
        assert rows[f"/tracks/{lab}/std"] == n
        assert rows[f"/tracks/{lab}/nees"] == n  # truth is known at every measurement time
    with_nis = Counter(e.track_id for r in results for e in r.estimates
                       if e.nis is not None and e.status == "confirmed")
    for tid, n in with_nis.items():
        assert rows[f"/tracks/{short_id(tid)}/nis"] == n
    assert rows["/world/truth"] == len(truth)
    assert rows["/world/meas/pos"] == len(truth)
    assert rows["/events"] >= 2  # born and confirmed
    out = subprocess.run([str(rerun_cli), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr


def test_inspect_matches_own_computation(tmp_path: Path) -> None:
    path = tmp_path / "run.rrd"
    results, truth = _record(path)
    s = summarise(path)
    assert s.complete and s.dropped_bytes == 0
    confirmed = {e.track_id for r in results for e in r.estimates if e.status == "confirmed"}
    assert sorted(t.full_id for t in s.tracks) == sorted(confirmed)
    assert all(t.track_id == short_id(t.full_id) for t in s.tracks)
    est = [e for e in latest(results).values() if e.status == "confirmed"]
    err = np.array([e.x[[0, 2]] - truth[e.t_ns][[0, 2]] for e in est])
    nees = [float((e.x - truth[e.t_ns]) @ np.linalg.solve(e.P, e.x - truth[e.t_ns])) for e in est]
    assert s.position_rmse == pytest.approx(float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), rel=1e-9)
    assert s.nees.mean == pytest.approx(float(np.mean(nees)), rel=1e-9)
    assert s.nees.dof == 4 * len(nees)
    assert s.sensors == {"pos": len(truth)}
    assert s.counts["applied"] == len(truth) and s.counts["received"] == len(truth)
    assert json.loads(s.to_json())["nis"]["verdict"] in ("consistent", "too high", "too low")


def _inside_a_frame(data: bytes, at: int, tmp: Path) -> int:
    """The first cut at or after `at` that rerun's reader cannot read whole (a cut inside a frame,
    not on a boundary between two: where frames end depends on the flushes' wall-clock cadence)."""
    probe = tmp / "probe.rrd"
    for cut in range(at, len(data)):
        probe.write_bytes(data[:cut])
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "no footer": every cut has none
                list(RrdReader(str(probe)).stream())
        except RuntimeError:
            return cut
    raise AssertionError(f"no cut inside a frame after byte {at}")


@pytest.mark.parametrize("cut", ["footer", "mid_frame"], ids=["no-footer", "cut-mid-frame"])
def test_inspect_reads_damaged_files(tmp_path: Path, cut: str) -> None:
    path = tmp_path / "run.rrd"
    _record(path)
    data = path.read_bytes()
    bad = tmp_path / "bad.rrd"
    bad.write_bytes(data[:-16] if cut == "footer" else data[: _inside_a_frame(data, len(data) * 2 // 3, tmp_path)])
    s = summarise(bad)
    assert not s.complete
    assert s.tracks, "nothing recovered"
    if cut == "mid_frame":
        assert s.dropped_bytes > 0


def test_rotation_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    tr, dets, truth = maneuver_run()
    sink = RotatingSink(tmp_path, prefix="rot", layout=tr.layout, position_indices=tr.position_indices,
                        velocity_indices=tr.velocity_indices, rotate_bytes=150_000, rotate_s=1e9, flush_interval_s=0.0)
    for t, x in sorted(truth.items()):  # into the first file; scoring carries over to the next ones
        sink.log_truths([("target", t, x)])
    results = []
    for d in dets:
        r = tr.process([d])
        results.append(r)
        sink.log_step(r)
    sink.close()
    assert len(sink.files) >= 3, "no rotation happened"
    assert [p.name for p in sink.files] == sorted(p.name for p in sink.files)
    assert sum(sink.steps_per_file) == len(results)
    total: Counter[str] = Counter()
    for p in sink.files:
        for k, v in _rows(p).items():
            total[k] += v
    assert total["/record/estimates"] == sum(len(r.estimates) for r in results)
    assert total["/world/estimates"] == sum(1 for r in results for e in r.estimates if e.status == "confirmed")
    assert total["/world/tentative"] == sum(1 for r in results for e in r.estimates if e.status == "tentative")
    assert total["/world/meas/pos"] == len(dets)
    # every file on its own: the confirmed rows it holds, whatever file saw the confirmation event
    est = [e for e in latest(results).values() if e.status == "confirmed"]
    per_file = [sum(t.estimates for t in summarise(p).tracks) for p in sink.files]
    assert sum(per_file) == len(est)
    assert all(n > 0 for n in per_file[1:-1]), per_file  # not only the file that saw the confirmation
    whole = tmp_path / "whole.rrd"
    _record(whole)
    merged, single = summarise(sink.files), summarise(whole)
    assert [t.estimates for t in merged.tracks] == [t.estimates for t in single.tracks]
    assert merged.position_rmse == pytest.approx(single.position_rmse, rel=1e-12)
    assert merged.nees.mean == pytest.approx(single.nees.mean, rel=1e-12)
    assert summarise([tmp_path]).files == [str(p) for p in sorted(tmp_path.glob("*.rrd"))]


def test_identical_runs_give_identical_figures(tmp_path: Path) -> None:
    from tests.io.scenario_run import record_scenario

    for k in (1, 2):
        record_scenario("mix", tmp_path / f"run{k}.rrd", duration_s=10.0)
    a, b = summarise(tmp_path / "run1.rrd"), summarise(tmp_path / "run2.rrd")
    assert a.events.get("replay", 0) > 0, "no replays: the case this guards is not exercised"
    for field_ in ("tracks", "position_rmse", "nis", "nees", "sensors", "tentative_only", "counts", "ospa_m",
                   "gospa_m"):
        assert getattr(a, field_) == getattr(b, field_), field_


def test_ellipse_is_two_sigma() -> None:
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    pts = ellipse_points(np.array([1.0, -1.0]), cov)
    assert pts.shape == (33, 2)
    stacked = ellipse_points(np.zeros((3, 2)), np.stack([cov] * 3))
    np.testing.assert_allclose(stacked[1] + np.array([1.0, -1.0]), pts, rtol=1e-12)
    d = pts - np.array([1.0, -1.0])
    m = np.einsum("ij,ij->i", d, np.linalg.solve(cov, d.T).T)
    np.testing.assert_allclose(m, 4.0, rtol=1e-12)


def test_inspect_cli_json(tmp_path: Path) -> None:
    import sys

    path = tmp_path / "run.rrd"
    _record(path)
    out = subprocess.run([sys.executable, "-m", "fusion", "inspect", str(path), "--json"], capture_output=True,
                         text=True, timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    s = summarise(path)
    assert data["position_rmse"] == pytest.approx(s.position_rmse, rel=1e-12)
    assert data["nees"]["mean"] == pytest.approx(s.nees.mean, rel=1e-12)
    assert [t["track_id"] for t in data["tracks"]] == [t.track_id for t in s.tracks]
    text = subprocess.run([sys.executable, "-m", "fusion", "inspect", str(path)], capture_output=True, text=True,
                          timeout=120, cwd=Path(__file__).resolve().parents[2])
    assert "position RMSE against truth" in text.stdout and "complete" in text.stdout


def test_the_final_counts_reach_the_file_and_inspect_reads_them(tmp_path: Path) -> None:
    """Counts that change after the last rows (refusals at the door, or a recording thread's last
    snapshot) are written at close, at the same time as the counts before them: inspect takes the
    last row written at the newest time."""
    from fusion.io.inspect import summarise
    from fusion.io.rerun_sink import RerunSink

    tr, dets, _ = maneuver_run(seed=3)
    applied = [0]
    sink = RerunSink(tmp_path / "c.rrd", layout=tr.layout, position_indices=tr.position_indices,
                     velocity_indices=tr.velocity_indices, counts=lambda: {"applied": applied[0]},
                     flush_interval_s=0.0, view_interval_s=1e9)  # a record flush (and a counts row) per step
    for d in dets[:30]:
        r = tr.process([d])
        applied[0] += len(r.estimates)
        sink.log_step(r)
    written = applied[0]
    applied[0] = written + 7  # nothing pending: only the close can say so, in the same chunk as the rows before
    sink.close()
    assert summarise(tmp_path / "c.rrd").counts["applied"] == written + 7
