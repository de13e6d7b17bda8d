"""Headless summary of fusion recordings (.rrd): what `fusion inspect` prints.

Input: one file, or a set (the files of a rotated recording, a folder, a glob), merged in time
order. Each file is read with rerun's own reader (fusion.io.rrd_read: a file without its footer is
scanned whole, a file cut inside a frame is read up to its last complete frame). The figures come
from the data of record (fusion.io.inspect_read), which every file of a rotated set holds for its
own rows, so any one file is summarised on its own.

Runs: files are grouped into runs by the run id each recording carries (the files of a rotated
set share one; see fusion.io.inspect_read.run_key for the other ways). Several runs are taken as
independent runs of the same scenario: their tracks are listed apart (a `run` column) and the
NIS/NEES verdicts average over them (fusion.io.verdicts: Bar-Shalom's N-run test at each time, and
the time average with its correlation-aware interval).

Only the latest revision of each estimate (track, time, sensor) counts, and a retraction removes
it: identical runs give identical figures whatever the replays did. A track counts as confirmed
when one of its estimates is. OSPA/GOSPA (fusion.io.derive.set_distance_series) are computed here
from those latest revisions and the file's truth, at every scan time with truth: the confirmed
estimates at that time (a track's last sensor's row) against the true positions.
"""

from __future__ import annotations

import glob
import json
import os
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from fusion.io import derive
from fusion.io.inspect_read import RunRecord, file_meta, run_key
from fusion.io.rrd_read import FOOTER, read_chunks
from fusion.io.track_rows import OSPA_MAX_POINTS
from fusion.io.verdicts import Consistency, per_time, verdict


@dataclass
class TrackSummary:
    track_id: str  # the short label (fusion.io.labels.short_id)
    first_t_ns: int
    last_t_ns: int
    estimates: int
    position_rmse: float | None
    mean_nis: float | None
    mean_nees: float | None
    full_id: int = 0
    run: int = 1  # which run (1..N, in the order of the files) when several are given


@dataclass
class Summary:
    path: str
    size_bytes: int
    complete: bool  # every file has its footer (closed normally)
    dropped_bytes: int  # bytes after the last readable frame (0 when intact)
    t_first_ns: int | None
    t_last_ns: int | None
    duration_s: float
    sensors: dict[str, int]  # measured points per sensor
    tracks: list[TrackSummary]  # tracks that were confirmed at some time
    tentative_only: int  # tracks that never got confirmed (clutter, false starts)
    position_rmse: float | None
    nis: Consistency
    nees: Consistency
    counts: dict[str, int]
    events: dict[str, int]  # as logged: every event, and every withdrawal ("withdrawn <kind>") by a replay
    meta: dict[str, object] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    # mean OSPA / GOSPA over the scan times with truth, from the latest revisions (module docstring)
    ospa_m: float | None = None
    gospa_m: float | None = None
    ospa_times: int = 0
    runs: int = 1
    runs_by: str = "id"  # how files were told apart as runs (fusion.io.inspect_read.run_key)
    run_ids: list[str] = field(default_factory=list)

    @property
    def events_net(self) -> dict[str, int]:
        """Events that stood after the replays (logged minus withdrawn), replays and refusals apart:
        a function of the data, where `events` also counts what later replays withdrew."""
        ev = self.events
        return {k: v - ev.get(f"withdrawn {k}", 0) for k, v in ev.items()
                if not k.startswith("withdrawn ") and k != "replay" and v - ev.get(f"withdrawn {k}", 0)}

    def to_json(self) -> str:
        return json.dumps({**asdict(self), "events_net": self.events_net}, indent=2, sort_keys=True)


def expand(inputs: list[str | Path]) -> list[Path]:
    """Files, folders (their *.rrd) and globs, as a sorted list of files (rotated sets sort by time)."""
    out: set[Path] = set()
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            out.update(p.glob("*.rrd"))
        elif any(ch in str(item) for ch in "*?[") and not p.exists():
            out.update(Path(x) for x in glob.glob(str(item)))
        else:
            out.add(p)
    return sorted(out)


def summarise(path: str | Path | list[str | Path], *, runs_by: str = "id") -> Summary:
    """Read one recording or a set of them and summarise (see the module docstring)."""
    files = expand(path if isinstance(path, list) else [path])
    if not files:
        raise RuntimeError(f"no recordings in {path}")
    runs: dict[str, RunRecord] = {}
    size = dropped = 0
    complete = True
    for i, p in enumerate(files):
        n = p.stat().st_size
        size += n
        with p.open("rb") as f:
            f.seek(max(0, n - 64))
            complete &= FOOTER in f.read()
        chunks, lost = read_chunks(p)
        dropped += lost
        runs.setdefault(run_key(file_meta(chunks), i, runs_by), RunRecord()).add(chunks)
    s = _Scores()
    for r, rd in enumerate(runs.values(), start=1):
        s.add_run(r, rd)
    ts = [t for rd in runs.values() for t in rd.t]
    t0, t1 = (min(ts), max(ts)) if ts else (None, None)
    allsq = np.concatenate(s.sq) if s.sq else np.empty(0)
    first = next(iter(runs.values()))
    sensors: dict[str, int] = defaultdict(int)
    events: dict[str, int] = defaultdict(int)
    counts: dict[str, int] = defaultdict(int)
    for rd in runs.values():
        for d, src in ((sensors, rd.sensors), (events, rd.events)):
            for k, v in src.items():
                d[k] += v
        for k, (_, v) in rd.counts.items():
            counts[k] += v
    return Summary(
        path=str(files[0]) if len(files) == 1 else f"{len(files)} files", size_bytes=size, complete=complete,
        dropped_bytes=dropped, t_first_ns=t0, t_last_ns=t1,
        duration_s=0.0 if t0 is None or t1 is None else (t1 - t0) / 1e9, sensors=dict(sorted(sensors.items())),
        tracks=s.tracks, tentative_only=s.tentative, position_rmse=float(np.sqrt(allsq.mean())) if allsq.size else None,
        nis=s.verdict("nis", len(runs)), nees=s.verdict("nees", len(runs)), counts=dict(sorted(counts.items())),
        events=dict(sorted(events.items())), meta=first.meta, files=[str(p) for p in files],
        ospa_m=float(np.mean(s.ospa)) if s.ospa else None, gospa_m=float(np.mean(s.gospa)) if s.gospa else None,
        ospa_times=len(s.ospa), runs=len(runs), runs_by=runs_by, run_ids=list(runs),
    )


class _Scores:
    """Per confirmed track of each run, from the latest revision of each estimate; NIS/NEES samples
    with their run, time and track sequence; OSPA/GOSPA per scan time."""

    def __init__(self) -> None:
        self.tracks: list[TrackSummary] = []
        self.sq: list[np.ndarray] = []
        self.samples: dict[str, dict[str, list]] = {k: defaultdict(list) for k in ("nis", "nees")}
        self.ospa: list[float] = []
        self.gospa: list[float] = []
        self.tentative = 0

    def add_run(self, run: int, rd: RunRecord) -> None:
        est = rd.est
        pos_idx = [int(i) for i in rd.meta.get("position_indices", [])]  # type: ignore[union-attr]
        by_track: dict[int, list[int]] = defaultdict(list)
        rows = rd.latest()
        for i in rows:
            by_track[est["track"][i]].append(i)
        for tid in sorted(by_track, key=lambda x: (est["label"][by_track[x][0]], x)):
            conf = [i for i in by_track[tid] if est["status"][i] == "confirmed"]
            if not conf:
                self.tentative += 1
                continue
            self.tracks.append(self._track(run, tid, conf, est, pos_idx))
        conf_rows = [i for i in rows if est["status"][i] == "confirmed"]
        truth = rd.truth_points(pos_idx) if pos_idx else {}
        if truth and conf_rows:
            t = np.asarray([est["t"][i] for i in conf_rows], dtype=np.int64)
            W = derive.world(np.asarray([est["x"][i] for i in conf_rows])[:, pos_idx])
            scan = np.asarray(sorted(rd.scan_t | set(est["t"][i] for i in rows)), dtype=np.int64)
            o, g = derive.set_distance_series(t, np.asarray([est["track"][i] for i in conf_rows]), W, truth, scan,
                                              max_points=OSPA_MAX_POINTS)
            self.ospa += o.tolist()
            self.gospa += g.tolist()

    def _track(self, run: int, tid: int, conf: list[int], est: dict[str, list], pos_idx: list[int]) -> TrackSummary:
        errs = [est["error"][i] for i in conf if est["nees_dof"][i]]  # scored against truth
        sq = np.sum(np.asarray(errs)[:, pos_idx] ** 2, axis=1) if errs and pos_idx else None
        if sq is not None:
            self.sq.append(sq)
        means = {}
        for name in ("nis", "nees"):
            use = [i for i in conf if est[f"{name}_dof"][i]]
            smp = self.samples[name]
            smp["v"] += [est[name][i] for i in use]
            smp["dof"] += [est[f"{name}_dof"][i] for i in use]
            smp["t"] += [est["t"][i] for i in use]
            smp["run"] += [run] * len(use)
            smp["seqs"].append(np.array([est[name][i] for i in use], dtype=np.float64))
            means[name] = float(np.mean(smp["seqs"][-1])) if use else None
        ts = [est["t"][i] for i in conf]
        return TrackSummary(est["label"][conf[0]], min(ts), max(ts), len(conf),
                            None if sq is None else float(np.sqrt(sq.mean())), means["nis"], means["nees"], int(tid),
                            run)

    def verdict(self, name: str, runs: int) -> Consistency:
        smp = self.samples[name]
        v, d = np.asarray(smp["v"], dtype=np.float64), np.asarray(smp["dof"], dtype=np.float64)
        c = verdict(v, d, smp["seqs"], runs=runs)
        if runs > 1:
            c.per_time = per_time(np.asarray(smp["t"], dtype=np.int64), np.asarray(smp["run"]), v, d)
        return c


def _table(tracks: list[TrackSummary], *, runs: bool) -> list[str]:
    head = ["track", "first [s]", "last [s]", "span [s]", "estimates", "RMSE [m]", "mean NIS", "mean NEES"]
    f = lambda v, p: "-" if v is None else f"{v:.{p}f}"  # noqa: E731
    rows = [[t.track_id, f(t.first_t_ns / 1e9, 3), f(t.last_t_ns / 1e9, 3), f((t.last_t_ns - t.first_t_ns) / 1e9, 2),
             str(t.estimates), f(t.position_rmse, 3), f(t.mean_nis, 2), f(t.mean_nees, 2)] for t in tracks]
    if runs:
        head, rows = ["run", *head], [[str(t.run), *r] for t, r in zip(tracks, rows, strict=True)]
    w = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    return ["  " + "  ".join(x.rjust(n) for x, n in zip(r, w, strict=True)) for r in [head, *rows]]


_RUNS_BY = {"id": "told apart by the run id each recording carries",
            "files": "each file taken as one run (--runs files)", "one": "all files taken as one run (--runs one)"}


def _consistency_lines(name: str, c: Consistency) -> list[str]:
    if c.mean is None:
        return [f"{name}: no data"]
    lo, hi = c.interval  # type: ignore[misc]
    out = [f"{name}: mean {c.mean:.3f} over {c.samples} samples, 95 % interval [{lo:.3f}, {hi:.3f}]: "
           f"{c.describe()} ({c.assumes})"]
    pt = c.per_time
    if pt is not None and pt.times and pt.interval is not None:
        out.append(f"  averaged over the {pt.runs} runs at each time held by all of them: {pt.inside} of {pt.times} "
                   f"times inside their 95 % interval (chi2(n N) / N: [{pt.interval[0]:.3f}, {pt.interval[1]:.3f}] "
                   f"at the first; 95 % expected, scattering more than a binomial's as the times are correlated)")
    return out


def format_summary(s: Summary) -> str:
    """The human-readable report."""
    lines = [f"{s.path}: {s.size_bytes / 1e6:.2f} MB, "
             + ("complete" if s.complete else "NO FOOTER (the writer did not close it: crashed or killed)")
             + (f", {s.dropped_bytes} trailing bytes unreadable" if s.dropped_bytes else "")]
    if len(s.files) > 1:
        lines.append("files: " + ", ".join(Path(f).name for f in s.files))
        no_id = s.runs_by == "id" and "" in s.run_ids
        lines.append(f"runs: {s.runs} ({_RUNS_BY[s.runs_by]}"
                     + ("; files without one, from before run ids, are taken as one run: --runs files if each is an "
                        "independent run" if no_id else "")
                     + ("; taken as independent runs of the same scenario" if s.runs > 1 else "") + ")")
    if s.t_first_ns is not None:
        lines.append(f"time span: {s.duration_s:.3f} s (t = {s.t_first_ns / 1e9:.3f} .. {s.t_last_ns / 1e9:.3f} s)")
    lines.append("sensors: " + (", ".join(f"{k} ({v} points)" for k, v in s.sensors.items()) or "none"))
    lines.append(f"tracks: {len(s.tracks)} confirmed, {s.tentative_only} never confirmed")
    if s.tracks:
        lines.extend(_table(s.tracks, runs=s.runs > 1))
    if s.position_rmse is not None:
        lines.append(f"position RMSE against truth: {s.position_rmse:.4f} m")
    if s.ospa_m is not None:
        lines.append(f"OSPA against truth: mean {s.ospa_m:.3f} m, GOSPA mean {s.gospa_m:.3f} m (order 2, cut-off "
                     f"{derive.OSPA_C_M:g} m; over {s.ospa_times} scan times with truth, from the latest revision of "
                     "each confirmed estimate)")
    for name, c in (("NIS", s.nis), ("NEES", s.nees)):
        lines.extend(_consistency_lines(name, c))
    if s.counts:
        lines.append("counts: " + ", ".join(f"{k}={v}" for k, v in s.counts.items()))
    if s.events:
        lines.append("events: " + ", ".join(f"{k}={v}" for k, v in s.events_net.items())
                     + " (those that stood after the replays)")
        withdrawn = sum(v for k, v in s.events.items() if k.startswith("withdrawn "))
        if s.events.get("replay"):
            lines.append(f"replays: {s.events['replay']}, which withdrew {withdrawn} events (these follow the arrival "
                         "order; the figures above do not)")
    return os.linesep.join(lines)
