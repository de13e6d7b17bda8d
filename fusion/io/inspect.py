"""Headless summary of a fusion recording (.rrd): what `fusion inspect` prints.

Reads the file with rerun's own reader. A file without its footer (a crashed or killed
service) is read by a whole-file scan; a file cut inside a frame is read up to the last
complete frame, and the summary says how many bytes were dropped.

Consistency verdicts: for K samples of NIS with m_k degrees of freedom, sum(NIS) ~ chi2(sum m_k);
the mean is "consistent" when the sum falls inside the two-sided 95 % interval of that
distribution (likewise NEES with n degrees of freedom per sample).
"""

from __future__ import annotations

import json
import os
import re
import tempfile
import warnings
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2

FOOTER = b"RRF2FOOT"


@dataclass
class TrackSummary:
    track_id: str
    first_t_ns: int
    last_t_ns: int
    estimates: int
    position_rmse: float | None
    mean_nis: float | None
    mean_nees: float | None


@dataclass
class Consistency:
    samples: int
    dof: int
    mean: float | None
    interval: tuple[float, float] | None  # 95 % interval of the mean
    verdict: str  # "consistent" | "too high" | "too low" | "no data"


@dataclass
class Summary:
    path: str
    size_bytes: int
    complete: bool  # the footer is present (closed normally)
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
    events: dict[str, int]
    meta: dict[str, object] = field(default_factory=dict)

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)


def _verdict(values: list[float], dofs: list[int]) -> Consistency:
    if not values:
        return Consistency(0, 0, None, None, "no data")
    k, dof = len(values), int(sum(dofs))
    total = float(np.sum(values))
    lo, hi = chi2.ppf(0.025, dof), chi2.ppf(0.975, dof)
    verdict = "consistent" if lo <= total <= hi else ("too high" if total > hi else "too low")
    return Consistency(k, dof, total / k, (float(lo / k), float(hi / k)), verdict)


def _chunks(path: Path) -> tuple[list[object], int]:
    """All chunks of the file, and the number of bytes that had to be dropped to read it."""
    from rerun.chunk import RrdReader

    def read(p: Path) -> list[object]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "no footer/manifest": we report that ourselves
            return list(RrdReader(str(p)).stream())

    try:
        return read(path), 0
    except RuntimeError as e:
        m = re.search(r"start (\d+)", str(e))
        if m is None:
            raise
        start = int(m.group(1))
    data = path.read_bytes()
    with tempfile.TemporaryDirectory() as tmp:
        cut = Path(tmp) / "prefix.rrd"
        for back in range(0, 65):  # the frame header sits just before the payload start
            cut.write_bytes(data[: start - back])
            try:
                return read(cut), len(data) - (start - back)
            except RuntimeError:
                continue
    raise RuntimeError(f"{path}: no readable prefix before byte {start}")


def _scalars(batch: object) -> tuple[np.ndarray, np.ndarray]:
    """(t, values (rows, k)) of a Scalars chunk; k components per row."""
    b = batch  # pyarrow RecordBatch
    t = b.column("t").cast("int64").to_numpy()  # type: ignore[attr-defined]
    rows = b.column("Scalars:scalars").to_pylist()  # type: ignore[attr-defined]
    k = max((len(r) for r in rows if r), default=1)
    v = np.array([r if r and len(r) == k else [np.nan] * k for r in rows], dtype=np.float64).reshape(len(rows), k)
    return t, v


def summarise(path: str | Path) -> Summary:
    """Read a recording and summarise it (see the module docstring)."""
    p = Path(path)
    size = p.stat().st_size
    with p.open("rb") as f:
        f.seek(max(0, size - 64))
        complete = FOOTER in f.read()
    chunks, dropped = _chunks(p)
    series: dict[str, list[tuple[np.ndarray, np.ndarray]]] = defaultdict(list)
    sensors: dict[str, int] = defaultdict(int)
    track_rows: dict[str, list[np.ndarray]] = defaultdict(list)
    events: dict[str, int] = defaultdict(int)
    confirmed_ids: set[str] = set()
    tentative_rows: set[str] = set()
    meta: dict[str, object] = {}
    t_all: list[int] = []
    for ch in chunks:
        ent: str = ch.entity_path  # type: ignore[attr-defined]
        b = ch.to_record_batch()  # type: ignore[attr-defined]
        names = b.schema.names
        parts = ent.strip("/").split("/")
        if ent == "/meta" and "TextDocument:text" in names:
            meta = json.loads(b.column("TextDocument:text").to_pylist()[0][0])
            continue
        if "t" in names and b.num_rows:
            t = b.column("t").cast("int64").to_numpy()
            t_all.extend((int(t.min()), int(t.max())))
        if ent == "/world/tentative":
            tentative_rows.update(x[0] for x in b.column("Points2D:labels" if "Points2D:labels" in names
                                                         else "Points3D:labels").to_pylist() if x)
        elif parts[:2] == ["world", "meas"] and len(parts) == 3:
            sensors[parts[2]] += sum(len(x) for x in b.column("Points2D:positions" if "Points2D:positions" in names
                                                              else "Points3D:positions").to_pylist())
        elif parts[:2] == ["world", "tracks"] and len(parts) == 3:
            track_rows[parts[2]].append(b.column("t").cast("int64").to_numpy())
        elif parts[0] in ("tracks", "counts") and "Scalars:scalars" in names:
            series[ent.strip("/")].append(_scalars(b))
        elif ent == "/events" and "TextLog:text" in names:
            for txt in b.column("TextLog:text").to_pylist():
                s = txt[0] if txt else ""
                m = re.match(r"track (\d+) (\w+)", s)
                kind = m.group(2) if m else s.split(" ", 1)[0]
                events[kind] += 1
                if m and kind == "confirmed":
                    confirmed_ids.add(m.group(1))

    def joined(name: str) -> tuple[np.ndarray, np.ndarray]:
        """(t, values (rows, k)) of a series, in time order."""
        parts_ = series.get(name, [])
        if not parts_:
            return np.empty(0, dtype=np.int64), np.empty((0, 1))
        t = np.concatenate([a for a, _ in parts_])
        v = np.concatenate([b for _, b in parts_])
        o = np.argsort(t, kind="stable")
        return t[o], v[o]

    layout = [str(x) for x in meta.get("layout", [])]  # type: ignore[union-attr]
    pos_idx = [int(i) for i in meta.get("position_indices", [])]  # type: ignore[union-attr]
    n_state = len(layout)
    tracks: list[TrackSummary] = []
    all_sq: list[np.ndarray] = []
    nis_v: list[float] = []
    nis_d: list[int] = []
    nees_v: list[float] = []
    for tid in sorted(confirmed_ids & set(track_rows), key=lambda s: int(s) if s.isdigit() else s):
        ts = np.concatenate(track_rows[tid])
        sq = None
        _, err = joined(f"tracks/{tid}/error")
        if err.shape[0] and pos_idx and err.shape[1] == n_state:
            sq = np.sum(err[:, pos_idx] ** 2, axis=1)
            all_sq.append(sq)
        nis = joined(f"tracks/{tid}/nis")[1][:, 0]
        dof = joined(f"tracks/{tid}/nis_dof")[1][:, 0]
        nees = joined(f"tracks/{tid}/nees")[1][:, 0]
        nis_v.extend(nis.tolist())
        nis_d.extend(dof.astype(int).tolist() if dof.size == nis.size else [2] * nis.size)
        nees_v.extend(nees.tolist())
        tracks.append(TrackSummary(
            tid, int(ts.min()), int(ts.max()), int(ts.size),
            None if sq is None else float(np.sqrt(sq.mean())),
            float(nis.mean()) if nis.size else None, float(nees.mean()) if nees.size else None,
        ))
    counts = {}
    for name in sorted(series):
        if name.startswith("counts/"):
            t, v = joined(name)
            counts[name[len("counts/"):]] = int(v[-1, 0])
    t0 = min(t_all) if t_all else None
    t1 = max(t_all) if t_all else None
    allsq = np.concatenate(all_sq) if all_sq else np.empty(0)
    return Summary(
        path=str(p), size_bytes=size, complete=complete, dropped_bytes=dropped, t_first_ns=t0, t_last_ns=t1,
        duration_s=0.0 if t0 is None or t1 is None else (t1 - t0) / 1e9,
        sensors=dict(sorted(sensors.items())), tracks=tracks, tentative_only=len(tentative_rows - confirmed_ids),
        position_rmse=float(np.sqrt(allsq.mean())) if allsq.size else None,
        nis=_verdict(nis_v, nis_d), nees=_verdict(nees_v, [n_state] * len(nees_v)), counts=counts,
        events=dict(sorted(events.items())), meta=meta,
    )


def format_summary(s: Summary) -> str:
    """The human-readable report."""
    lines = [f"{s.path}: {s.size_bytes / 1e6:.2f} MB, "
             + ("complete" if s.complete else "NO FOOTER (the writer did not close it: crashed or killed)")
             + (f", {s.dropped_bytes} trailing bytes unreadable" if s.dropped_bytes else "")]
    if s.t_first_ns is not None:
        lines.append(f"time span: {s.duration_s:.3f} s (t = {s.t_first_ns} .. {s.t_last_ns} ns)")
    lines.append("sensors: " + (", ".join(f"{k} ({v} points)" for k, v in s.sensors.items()) or "none"))
    lines.append(f"tracks: {len(s.tracks)} confirmed, {s.tentative_only} never confirmed")
    for t in s.tracks:
        rm = "-" if t.position_rmse is None else f"{t.position_rmse:.3f}"
        lines.append(f"  {t.track_id:>20}  {(t.last_t_ns - t.first_t_ns) / 1e9:8.2f} s  {t.estimates:6d} estimates"
                     f"  rmse {rm}")
    if s.position_rmse is not None:
        lines.append(f"position RMSE against truth: {s.position_rmse:.4f}")
    for name, c in (("NIS", s.nis), ("NEES", s.nees)):
        if c.mean is None:
            lines.append(f"{name}: no data")
        else:
            lo, hi = c.interval  # type: ignore[misc]
            lines.append(f"{name}: mean {c.mean:.3f} over {c.samples} samples, 95 % interval [{lo:.3f}, {hi:.3f}]:"
                         f" {c.verdict}")
    if s.counts:
        lines.append("counts: " + ", ".join(f"{k}={v}" for k, v in s.counts.items()))
    if s.events:
        lines.append("events: " + ", ".join(f"{k}={v}" for k, v in s.events.items()))
    return os.linesep.join(lines)
