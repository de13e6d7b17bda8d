"""Headless summary of fusion recordings (.rrd): what `fusion inspect` prints.

Input: one file, or a set (the files of a rotated recording, a folder, a glob), merged in time
order. Each file is read with rerun's own reader (fusion.io.rrd_read: a file without its footer is
scanned whole, a file cut inside a frame is read up to its last complete frame). The figures come
from the data of record (`record/estimates`, `record/events`: columns, no text is parsed), which
every file of a rotated set holds for its own rows, so any one file is summarised on its own.

Only the latest revision of each estimate (track, time, sensor) counts, and a retraction removes
it: identical runs give identical figures whatever the replays did. A track counts as confirmed
when one of its estimates is.

Consistency verdicts (NIS over the measurement dimension m_k of each update; NEES over the
kinematic components n, see fusion.io.derive): for K independent samples sum(values) ~
chi2(sum(dofs)). Estimation errors are correlated in time (NEES above all: a slowly forgetting
filter carries its initial error for the whole run), so the samples are not independent: the
verdict estimates the integrated autocorrelation time tau of the samples (each track's in time
order; Geyer's initial positive sequence; about the sample mean, corrected for that estimator's
low bias in runs of L samples, E[tau_hat] ~ tau (1 - tau / L)) and tests the mean against the interval of K / tau
effectively independent samples: chi2.ppf((0.025, 0.975), sum(dofs) / tau) / (K / tau). White
samples (NIS of a consistent filter) give tau ~ 1, the plain chi-square test. Several files of
independent runs give more effectively independent samples. The verdict says what it assumed.
"""

from __future__ import annotations

import glob
import json
import os
from collections import defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from fusion.io.rrd_read import FOOTER, read_chunks


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


@dataclass
class Consistency:
    samples: int
    dof: int  # total degrees of freedom
    mean: float | None  # mean value per sample
    interval: tuple[float, float] | None  # 95 % interval of the mean per sample
    verdict: str  # "consistent" | "too high" | "too low" | "no data"
    assumes: str = ""


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
    events: dict[str, int]
    meta: dict[str, object] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)
    # mean OSPA / GOSPA of the recording's metrics series: computed when logged, from the revisions
    # known then, so (unlike every other figure here) they can differ between identical runs with replays
    ospa_m: float | None = None
    gospa_m: float | None = None

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)


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


def autocorrelation_time(seqs: list[np.ndarray], mean: float) -> float:
    """Integrated autocorrelation time tau = 1 + 2 sum_k rho_k of samples pooled over sequences
    (each track's samples in time order), rho from the pooled autocovariance about `mean` (the
    value under test: the sample mean would hide an error that persists for the whole run), by
    FFT, the sum cut by Geyer's initial positive sequence (pairs rho_2m + rho_2m+1 summed while
    positive). At least 1."""
    seqs = [q for q in seqs if q.size > 1]
    if not seqs:
        return 1.0
    mu = mean
    n_max = max(q.size for q in seqs)
    acov = np.zeros(n_max)
    pairs = np.zeros(n_max)
    for q in seqs:
        x = q - mu
        f = np.fft.rfft(x, 2 * q.size)
        acov[: q.size] += np.fft.irfft(f * np.conj(f))[: q.size]
        pairs[: q.size] += np.arange(q.size, 0, -1)
    if acov[0] <= 0:
        return 1.0
    rho = (acov / pairs) / (acov[0] / pairs[0])
    tau = -1.0
    for m in range(n_max // 2):
        g = rho[2 * m] + rho[2 * m + 1]
        if g <= 0:
            break
        tau += 2.0 * g
    return max(tau, 1.0)


def verdict(values: np.ndarray, dofs: np.ndarray, seqs: list[np.ndarray] | None = None) -> Consistency:
    """See the module docstring. values, dofs: per sample; seqs: the values per track in time order
    (for the autocorrelation; one sequence of all values when not given)."""
    k = int(values.size)
    if k == 0:
        return Consistency(0, 0, None, None, "no data", "")
    total, dof = float(values.sum()), int(dofs.sum())
    seqs_ = seqs if seqs is not None else [values]
    tau_hat = autocorrelation_time(seqs_, float(values.mean()))
    # about the sample mean, the estimate is biased low: E[tau_hat] ~ tau (1 - tau / L) for
    # sequences of L samples; solved for tau (capped at L / 2)
    L = float(np.mean([q.size for q in seqs_ if q.size > 1] or [k]))
    tau = L / 2 * (1 - np.sqrt(1 - 4 * tau_hat / L)) if tau_hat < L / 4 else L / 2
    tau = max(float(tau), 1.0)
    k_eff = k / tau
    nu = dof / tau  # chi-square degrees of freedom of the k_eff effectively independent samples
    lo, hi = chi2.ppf(0.025, nu) / k_eff, chi2.ppf(0.975, nu) / k_eff
    mean = total / k
    verdict_ = "consistent" if lo <= mean <= hi else ("too high" if mean > hi else "too low")
    return Consistency(k, dof, mean, (float(lo), float(hi)), verdict_,
                       f"time-correlated samples: autocorrelation time {tau:.1f} samples, so {k_eff:.0f} "
                       f"effectively independent ones; sum ~ chi2(sum of dofs / {tau:.1f}) scaled")


class _Reader:
    """What the summary needs from the chunks of one or more files."""

    def __init__(self) -> None:
        self.est: dict[str, list] = defaultdict(list)
        self.sensors: dict[str, int] = defaultdict(int)
        self.events: dict[str, int] = defaultdict(int)
        self.counts: dict[str, tuple[int, int]] = {}  # name -> (t, value)
        self.metrics: dict[str, list[float]] = defaultdict(list)
        self.meta: dict[str, object] = {}
        self.t: list[int] = []

    def add(self, chunks: list) -> None:
        for ch in chunks:
            ent: str = ch.entity_path
            b = ch.to_record_batch()
            names = b.schema.names
            if ent == "/meta" and "TextDocument:text" in names:
                self.meta = json.loads(b.column("TextDocument:text").to_pylist()[0][0])
                continue
            if "t" not in names or not b.num_rows:
                continue
            t = b.column("t").cast("int64").to_numpy()
            self.t.extend((int(t.min()), int(t.max())))
            if ent == "/record/estimates":
                self.est["t"].extend(t.tolist())
                for k in ("track", "label", "sensor", "status", "revision", "nis", "nis_dof", "nees", "nees_dof"):
                    self.est[k].extend(v[0] if v else None for v in b.column(k).to_pylist())
                self.est["error"].extend(b.column("error").to_pylist())  # a vector per row (the batch itself)
            elif ent == "/record/events":
                for kind, retracted in zip(b.column("kind").to_pylist(), b.column("retracted").to_pylist(),
                                           strict=True):
                    self.events[("withdrawn " if retracted[0] else "") + kind[0]] += 1
            elif ent.startswith("/world/meas/") and "Points3D:positions" in names:
                self.sensors[ent.rsplit("/", 1)[1]] += sum(len(x) for x in b.column("Points3D:positions").to_pylist())
            elif ent.startswith("/counts/") and "Scalars:scalars" in names:
                v = b.column("Scalars:scalars").to_pylist()
                i = int(np.argmax(t))
                name = ent[len("/counts/"):]
                if name not in self.counts or int(t[i]) >= self.counts[name][0]:
                    self.counts[name] = (int(t[i]), int(v[i][0]))
            elif ent.startswith("/metrics/") and "Scalars:scalars" in names:
                self.metrics[ent[len("/metrics/"):]].extend(x[0] for x in b.column("Scalars:scalars").to_pylist())


def summarise(path: str | Path | list[str | Path]) -> Summary:
    """Read one recording or a set of them and summarise (see the module docstring)."""
    files = expand(path if isinstance(path, list) else [path])
    if not files:
        raise RuntimeError(f"no recordings in {path}")
    rd = _Reader()
    size = dropped = 0
    complete = True
    for p in files:
        n = p.stat().st_size
        size += n
        with p.open("rb") as f:
            f.seek(max(0, n - 64))
            complete &= FOOTER in f.read()
        chunks, lost = read_chunks(p)
        dropped += lost
        rd.add(chunks)
    pos_idx = [int(i) for i in rd.meta.get("position_indices", [])]  # type: ignore[union-attr]
    tracks, all_sq, nis, nees, tentative = _tracks(rd.est, pos_idx)
    t0 = min(rd.t) if rd.t else None
    t1 = max(rd.t) if rd.t else None
    allsq = np.concatenate(all_sq) if all_sq else np.empty(0)
    mean = lambda v: float(np.mean(v)) if v else None  # noqa: E731
    return Summary(
        path=str(files[0]) if len(files) == 1 else f"{len(files)} files", size_bytes=size, complete=complete,
        dropped_bytes=dropped, t_first_ns=t0, t_last_ns=t1,
        duration_s=0.0 if t0 is None or t1 is None else (t1 - t0) / 1e9, sensors=dict(sorted(rd.sensors.items())),
        tracks=tracks, tentative_only=tentative,
        position_rmse=float(np.sqrt(allsq.mean())) if allsq.size else None,
        nis=verdict(*nis), nees=verdict(*nees), counts={k: v for k, (_, v) in sorted(rd.counts.items())},
        events=dict(sorted(rd.events.items())), meta=rd.meta, files=[str(p) for p in files],
        ospa_m=mean(rd.metrics.get("ospa")), gospa_m=mean(rd.metrics.get("gospa")),
    )


def _tracks(est: dict[str, list], pos_idx: list[int]) -> tuple:
    """Per confirmed track, from the latest revision of each estimate."""
    latest: dict[tuple[int, int, str], int] = {}
    for i, key in enumerate(zip(est["track"], est["t"], est["sensor"], strict=True)):
        j = latest.get(key)
        if j is None or est["revision"][i] >= est["revision"][j]:
            latest[key] = i
    rows = sorted((k[0], k[1], i) for k, i in latest.items() if est["status"][i] != "retracted")
    by_track: dict[int, list[int]] = defaultdict(list)
    for tid, _, i in rows:
        by_track[tid].append(i)
    tracks, all_sq = [], []
    nis_v, nis_d, nees_v, nees_d = [], [], [], []
    nis_s, nees_s = [], []  # per track, in time order: for the autocorrelation
    tentative = 0
    for tid in sorted(by_track, key=lambda x: est["label"][by_track[x][0]]):
        idx = by_track[tid]
        conf = [i for i in idx if est["status"][i] == "confirmed"]
        if not conf:
            tentative += 1
            continue
        errs = [est["error"][i] for i in conf if est["nees_dof"][i]]  # scored against truth
        sq = np.sum(np.asarray(errs)[:, pos_idx] ** 2, axis=1) if errs and pos_idx else None
        if sq is not None:
            all_sq.append(sq)
        ni = [i for i in conf if est["nis_dof"][i]]
        ne = [i for i in conf if est["nees_dof"][i]]
        nis_v += [est["nis"][i] for i in ni]
        nis_d += [est["nis_dof"][i] for i in ni]
        nees_v += [est["nees"][i] for i in ne]
        nees_d += [est["nees_dof"][i] for i in ne]
        nis_s.append(np.array([est["nis"][i] for i in ni]))
        nees_s.append(np.array([est["nees"][i] for i in ne]))
        ts = [est["t"][i] for i in conf]
        tracks.append(TrackSummary(
            est["label"][conf[0]], min(ts), max(ts), len(conf), None if sq is None else float(np.sqrt(sq.mean())),
            float(np.mean([est["nis"][i] for i in ni])) if ni else None,
            float(np.mean([est["nees"][i] for i in ne])) if ne else None, int(tid)))
    arr = lambda v: np.asarray(v, dtype=np.float64)  # noqa: E731
    return tracks, all_sq, (arr(nis_v), arr(nis_d), nis_s), (arr(nees_v), arr(nees_d), nees_s), tentative


def _table(tracks: list[TrackSummary]) -> list[str]:
    head = ["track", "first [s]", "last [s]", "span [s]", "estimates", "RMSE [m]", "mean NIS", "mean NEES"]
    f = lambda v, p: "-" if v is None else f"{v:.{p}f}"  # noqa: E731
    rows = [[t.track_id, f(t.first_t_ns / 1e9, 3), f(t.last_t_ns / 1e9, 3), f((t.last_t_ns - t.first_t_ns) / 1e9, 2),
             str(t.estimates), f(t.position_rmse, 3), f(t.mean_nis, 2), f(t.mean_nees, 2)] for t in tracks]
    w = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    return ["  " + "  ".join(x.rjust(n) for x, n in zip(r, w, strict=True)) for r in [head, *rows]]


def format_summary(s: Summary) -> str:
    """The human-readable report."""
    lines = [f"{s.path}: {s.size_bytes / 1e6:.2f} MB, "
             + ("complete" if s.complete else "NO FOOTER (the writer did not close it: crashed or killed)")
             + (f", {s.dropped_bytes} trailing bytes unreadable" if s.dropped_bytes else "")]
    if len(s.files) > 1:
        lines.append("files: " + ", ".join(Path(f).name for f in s.files))
    if s.t_first_ns is not None:
        lines.append(f"time span: {s.duration_s:.3f} s (t = {s.t_first_ns / 1e9:.3f} .. {s.t_last_ns / 1e9:.3f} s)")
    lines.append("sensors: " + (", ".join(f"{k} ({v} points)" for k, v in s.sensors.items()) or "none"))
    lines.append(f"tracks: {len(s.tracks)} confirmed, {s.tentative_only} never confirmed")
    if s.tracks:
        lines.extend(_table(s.tracks))
    if s.position_rmse is not None:
        lines.append(f"position RMSE against truth: {s.position_rmse:.4f} m")
    if s.ospa_m is not None:
        lines.append(f"OSPA against truth: mean {s.ospa_m:.3f} m, GOSPA mean {s.gospa_m:.3f} m (order 2, cut-off 10 m, "
                     "as logged: before later revisions)")
    for name, c in (("NIS", s.nis), ("NEES", s.nees)):
        if c.mean is None:
            lines.append(f"{name}: no data")
        else:
            lo, hi = c.interval  # type: ignore[misc]
            lines.append(f"{name}: mean {c.mean:.3f} over {c.samples} samples, 95 % interval [{lo:.3f}, {hi:.3f}]:"
                         f" {c.verdict} ({c.assumes})")
    if s.counts:
        lines.append("counts: " + ", ".join(f"{k}={v}" for k, v in s.counts.items()))
    if s.events:
        lines.append("events: " + ", ".join(f"{k}={v}" for k, v in s.events.items()))
    return os.linesep.join(lines)
