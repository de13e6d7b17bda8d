"""The soak: the service as shipped (`fusion serve --config configs/service.toml`, recording on)
fed 10k measurements/s for `duration_s`, its resident memory (fusion.io.memory: total, anonymous,
file-backed) and status counts sampled every `every_s` (10 s by default; 1-2 s to see a
saw-tooth). Figures over the samples after the first minute: median, 5-95 %, min-max and
max/min - 1 (goal 6: within 10 %), the least-squares slope and the two halves' means; a soak
whose queue grew (the loop did not keep up) holds a backlog in memory and is not a measurement
of the service's footprint: applied, refused and the most queued are reported beside it.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from bench.e2e_load import MSGS_PER_TARGET_S
from bench.e2e_procs import Publisher, ServiceProcess, prime
from fusion.io.memory import process_memory


def soak_run(pub: Publisher, folder: Path, *, duration_s: float, rate: int = 10_000, every_s: float = 10.0,
             recording: bool = True) -> dict:
    """The soak; its heading and each sample printed as they come (a 30-minute soak shows how it
    goes while it runs), the summary after (print_soak)."""
    targets = round(rate / MSGS_PER_TARGET_S)
    folder.mkdir()
    print(heading(rate, targets, duration_s, recording, every_s), flush=True)
    samples: list[dict[str, Any]] = []
    with ServiceProcess(folder, recording=recording) as svc:
        pub.call("connect", svc.endpoint)
        prime(svc, pub, timeout_s=120.0)
        start_ns = time.time_ns() + 1_000_000_000
        pub.send("paced", {"targets": targets, "seed": 11, "start_ns": start_ns, "duration_s": duration_s})
        t0 = time.monotonic() + 1.0
        k = 0
        while True:
            wait = t0 + k * every_s - time.monotonic()
            if pub.conn.poll(max(wait, 0.0)):
                break
            st = svc.status()
            mem = process_memory(svc.pid)
            samples.append({"t_s": k * every_s, "rss_mb": mem.rss_mb, "anon_mb": mem.anon_mb, "file_mb": mem.file_mb,
                            "queued": st.counts.queued if st else None, "applied": st.counts.applied if st else None,
                            "recording_bytes": st.recording_bytes if st else None})
            print(sample_line(samples[-1]), flush=True)
            k += 1
        sent = pub.result(60.0)
        st = svc.status()
        end_rss = svc.rss_kb() / 1024
        pub.call("disconnect")
    c = st.counts if st else None
    return {
        "duration_s": duration_s, "rate": rate, "recording": recording, "targets": targets, "sent": sent["sent"],
        "every_s": every_s, "samples": samples, "rss_end_mb": end_rss, **soak_figures(samples),
        "applied": None if c is None else c.applied, "queued_end": None if c is None else c.queued,
        "refused": None if c is None else dict(c.refused),
        "recording_bytes_per_meas": None if st is None or not c.applied else st.recording_bytes / c.applied,
    }


def soak_figures(samples: list[dict[str, Any]], *, settle_s: float = 60.0) -> dict[str, Any]:
    """Over a soak's samples (t_s, rss_mb, anon_mb, queued): start, min and max RSS and its slope
    (least squares, MB per minute) over all samples, and over those after `settle_s` (the first
    minute: imports, compiled kernels, the tracks' birth, the history window filling) the spread
    max/min - 1 of RSS and of anonymous memory, min, max, median, 5th and 95th percentiles, the
    means of the first and second half, the largest step between neighbouring samples, slope and
    the largest backlog (queued)."""
    rss = np.array([s["rss_mb"] for s in samples])
    anon = np.array([s["anon_mb"] for s in samples])
    t = np.array([s["t_s"] for s in samples])
    after = t >= settle_s if (t >= settle_s).sum() >= 2 else np.ones(len(t), dtype=bool)
    late = rss[after]
    halves = np.array_split(late, 2)

    def slope(tt: np.ndarray, y: np.ndarray) -> float:
        return float(np.polyfit(tt, y, 1)[0] * 60) if len(y) >= 2 else float("nan")

    queued = [s["queued"] for s, a in zip(samples, after.tolist(), strict=True) if a and s["queued"] is not None]
    at_settle = rss[np.searchsorted(t, settle_s)] if t[-1] >= settle_s else float("nan")
    return {
        "rss_start_mb": float(rss[0]), "rss_max_mb": float(rss.max()), "rss_min_mb": float(rss.min()),
        "slope_mb_per_min": slope(t, rss), "spread_after_1min": float(late.max() / late.min() - 1),
        "rss_at_1min_mb": float(at_settle),
        "anon_at_1min_mb": float(anon[np.searchsorted(t, settle_s)]) if t[-1] >= settle_s else float("nan"),
        "rss_min_after_1min_mb": float(late.min()), "rss_max_after_1min_mb": float(late.max()),
        "rss_median_after_1min_mb": float(np.median(late)),
        "rss_p5_after_1min_mb": float(np.percentile(late, 5)), "rss_p95_after_1min_mb": float(np.percentile(late, 95)),
        "rss_halves_after_1min_mb": [float(h.mean()) if len(h) else float("nan") for h in halves],
        "largest_step_after_1min_mb": float(np.abs(np.diff(late)).max()) if len(late) >= 2 else 0.0,
        "slope_after_1min_mb_per_min": slope(t[after], late),
        "anon_spread_after_1min": float(anon[after].max() / anon[after].min() - 1),
        "queued_max_after_1min": max(queued, default=None),
    }


def heading(rate: int, targets: int, duration_s: float, recording: bool, every_s: float) -> str:
    """What the soak runs, printed before its samples."""
    return (f"\nsoak: {rate}/s offered ({targets} targets) for {duration_s:.0f} s, recording "
            f"{'on' if recording else 'off'}; service VmRSS every {every_s:g} s (queued: as of the last status "
            f"refresh)")


def sample_line(s: dict[str, Any]) -> str:
    """One sample of the soak, as printed."""
    return (f"  t={s['t_s']:>5.0f} s  rss {s['rss_mb']:8.1f} MB (anon {s['anon_mb']:7.1f}, file {s['file_mb']:6.1f})"
            f"  queued {s['queued']}  applied {s['applied']}")


def print_soak(r: dict[str, Any]) -> None:
    """The soak's summary (soak_run printed its samples as they came; they are in r["samples"])."""
    h1, h2 = r["rss_halves_after_1min_mb"]
    print(f"\n| | VmRSS |\n|---|---|\n| start | {r['rss_start_mb']:.0f} MB |\n"
          f"| 60 s | {r['rss_at_1min_mb']:.0f} MB (anonymous {r['anon_at_1min_mb']:.0f} MB) |\n"
          f"| end | {r['rss_end_mb']:.0f} MB |\n| after 60 s: median | {r['rss_median_after_1min_mb']:.0f} MB |\n"
          f"| after 60 s: 5-95 % | {r['rss_p5_after_1min_mb']:.0f}-{r['rss_p95_after_1min_mb']:.0f} MB |\n"
          f"| after 60 s: min-max | {r['rss_min_after_1min_mb']:.0f}-{r['rss_max_after_1min_mb']:.0f} MB |\n"
          f"| after 60 s: max/min - 1 | {r['spread_after_1min']:.1%} (anonymous {r['anon_spread_after_1min']:.1%}) |\n"
          f"| after 60 s: slope | {r['slope_after_1min_mb_per_min']:+.1f} MB/min (whole run "
          f"{r['slope_mb_per_min']:+.1f}) |\n| after 60 s: halves | {h1:.0f} / {h2:.0f} MB |\n"
          f"| after 60 s: largest step between samples | {r['largest_step_after_1min_mb']:.0f} MB |")
    rb = r["recording_bytes_per_meas"]
    print(f"applied {r['applied']}, refused {r['refused']}, queued at the end {r['queued_end']}, most queued at a "
          f"sample after the first minute {r['queued_max_after_1min']} (a backlog is held in memory: the loop did "
          f"not keep up); recording {'n/a' if rb is None else f'{rb:.0f}'} bytes per measurement")


def run_soak(*, duration_s: float = 600.0, every_s: float = 10.0) -> dict[str, Any]:
    with tempfile.TemporaryDirectory(prefix="fusion-soak-") as d, Publisher() as pub:
        r = soak_run(pub, Path(d) / "soak", duration_s=duration_s, every_s=every_s) | {"loadavg_start": os.getloadavg()}
    r["loadavg_end"] = os.getloadavg()
    print_soak(r)
    return r
