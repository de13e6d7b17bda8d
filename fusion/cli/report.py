"""What a person reads: counts, the service's status and its tracks, in words that match the
numbers (a duplicate is a duplicate, not a refusal)."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

from fusion import messages as m
from fusion.io.labels import short_id
from fusion.tracking.detection import Reason
from fusion.tracking.results import Counts


def counts_line(c: Mapping[str, Any]) -> str:
    """received = applied + inputs + truth + duplicates + refused + queued, said for measurements
    (the truth samples a simulator sends beside them are not measurements; control inputs are
    said apart, applied or not: inputs + inputs_refused; truth_refused and other_refused: truth
    samples and samples on keys that name no kind among the refused)."""
    refused: Mapping[str, int] = c.get("refused", {})
    n_ref = sum(refused.values())
    inputs_refused, truth_refused = int(c.get("inputs_refused", 0)), int(c.get("truth_refused", 0))
    inputs = int(c.get("inputs", 0)) + inputs_refused
    other_refused = int(c.get("other_refused", 0))
    measurements = c["received"] - int(c.get("truth", 0)) - truth_refused - other_refused - inputs
    parts = [f"{c['applied']} applied", f"{c['duplicates']} duplicates dropped",
             f"{n_ref} refused" + (" (" + ", ".join(f"{k} {v}" for k, v in sorted(refused.items())) + ")"
                                   if refused else "")]
    if c.get("queued"):
        parts.append(f"{c['queued']} not yet processed")
    line = (f"received {measurements} measurements" + (f" and {inputs} control inputs" if inputs else "") + ": "
            + ", ".join(parts))
    others = [f"{word} {n}" for n, word in ((inputs_refused, "control inputs"), (truth_refused, "truth samples"),
                                            (other_refused, "samples on keys of no kind")) if n]
    if others:
        line += "; of the duplicates and refused: " + ", ".join(others)
    if c.get("late_applied"):
        line += f"; {c['late_applied']} late ones folded in by {c['replays']} replay{'s' if c['replays'] != 1 else ''}"
    return line + f"; published {c['published']} estimate messages (revisions included)"


def flat_counts(c: Counts, *, published: int) -> dict[str, Any]:
    """A pipeline's counts (fusion.tracking.results.Counts) in the shape counts_line reads:
    duplicates apart from the other refusals, reasons that did not happen left out."""
    refused = {r.value: n for r, n in sorted(c.refused.items()) if n and r != Reason.DUPLICATE}
    return {"received": c.received, "applied": c.applied, "duplicates": c.duplicates, "refused": refused,
            "truth": c.truth, "inputs": c.inputs, "inputs_refused": c.inputs_refused, "truth_refused": c.truth_refused,
            "other_refused": c.other_refused, "late_applied": c.late_applied, "replays": c.replays,
            "published": published}


def size(n_bytes: int) -> str:
    return f"{n_bytes / 1e6:.1f} MB" if n_bytes >= 100_000 else f"{n_bytes / 1e3:.1f} kB"


def duration(s: float) -> str:
    if s < 120:
        return f"{s:.1f} s"
    if s < 7200:
        return f"{int(s // 60)} min {int(s % 60)} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60)} min"


def format_status(st: m.ServiceStatus, namespace: str) -> str:
    c = st.counts
    tracks = ", ".join(f"{v} {k}" for k, v in sorted(st.tracks.items())) or "none"
    counts = {"received": c.received, "applied": c.applied, "duplicates": c.duplicates, "refused": c.refused,
              "queued": c.queued, "late_applied": c.late_applied, "replays": c.replays, "published": c.published,
              "truth": c.truth, "inputs": c.inputs, "inputs_refused": c.inputs_refused,
              "truth_refused": c.truth_refused, "other_refused": c.other_refused}
    lines = [
        f"fusion service on namespace {namespace!r}, up {duration(st.uptime_s)}",
        f"  samples    {counts_line(counts)}",
        f"  truth      {c.truth} samples" + (f" ({c.truth_refused} more refused)" if c.truth_refused else ""),
        f"  tracks     {tracks}",
        f"  queue      {st.queue_depth} waiting",
        "  recording  " + (f"{st.recording} ({size(st.recording_bytes)}"
                           + (f"; {st.recording_queue} rows still to write" if st.recording_queue else "") + ")"
                           if st.recording else "off"),
    ]
    if st.recording_error:
        lines.append(f"  recording  FAILED: {st.recording_error} (tracking and publishing go on)")
    if (cp := st.checkpoint) is not None:
        resumed = (f"resumed {cp.resumed_tracks} tracks from a checkpoint {duration(cp.resumed_age_s)} old"
                   if cp.resumed_age_s is not None else "started with no checkpoint")
        refused = f"; one found at start was refused: {cp.refused}" if cp.refused else ""
        last = (f"; last written {duration(cp.last_written_age_s)} ago" if cp.last_written_age_s is not None else "")
        err = f"; the last write FAILED: {cp.error}" if cp.error else ""
        lines.append(f"  checkpoint {cp.path}: {resumed}{refused}; {cp.written} written{last}{err}")
    if st.zenoh is not None:
        z = st.zenoh
        again = f", {z.reconnects} reconnects" if z.reconnects else ""
        lines.append(f"  zenoh      {z.mode} {z.state} ({z.routers} routers, {z.peers} peers; "
                     f"{z.connect_attempts} attempts to start{again})")
    for sensor, lat in sorted(st.latency.items()):
        # arrival - sensor time: below 0 when the sensor's times run ahead of their arrival
        ahead = (" (below 0: its times are ahead of when they arrive; a publisher faster than real time, or a clock "
                 "ahead of this machine's)" if lat.p50_ms < 0 else "")
        lines.append(f"  latency    {sensor}: mean {lat.mean_ms:.1f} ms, p50 {lat.p50_ms:.1f}, p99 {lat.p99_ms:.1f}, "
                     f"max {lat.max_ms:.1f} ms over {lat.count} measurements{ahead}")
    for sensor, g in sorted(st.gaps.items()):
        runs = f", {g.restarts} publisher restarts" if g.restarts else ""
        zen = f", {g.zenoh_missed} reported missed by zenoh" if g.zenoh_missed else ""
        lines.append(f"  seq gaps   {sensor}: {g.missing} missing, {g.filled} filled late{runs}{zen}")
    return "\n".join(lines)


_POSITION = ("x", "y", "z", "p")


def _time(t_ns: int) -> str:
    """Epoch times (after 1973) as UTC clock time; stream-relative times in seconds."""
    if t_ns > 10**17:
        return time.strftime("%H:%M:%S", time.gmtime(t_ns // 10**9)) + f".{t_ns % 10**9 // 10**6:03d}"
    return f"{t_ns / 1e9:.3f} s"


def format_tracks(snap: m.Snapshot, namespace: str) -> str:
    """One row per confirmed track: its latest estimate, the position's standard deviation."""
    est = sorted(snap.estimates, key=lambda e: e.track_id)
    if not est:
        return f"namespace {namespace!r}: no confirmed tracks right now"
    layout = est[0].layout
    head = ["track", "time", *layout, "pos std", "sensor", "NIS"]
    rows = []
    for e in est:
        n = len(e.state)
        pos = [i for i, name in enumerate(e.layout) if name in _POSITION]
        std = math.sqrt(sum(e.cov[i * n + i] for i in pos)) if pos and len(e.cov) == n * n else float("nan")
        rows.append([short_id(e.track_id), _time(e.t_ns), *(f"{v:.2f}" for v in e.state), f"{std:.2f}", e.sensor_id,
                     "-" if e.nis is None else f"{e.nis:.2f}"])
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    fmt = lambda r: "  ".join(x.rjust(w) for x, w in zip(r, widths, strict=True))  # noqa: E731
    model = est[0].model
    return "\n".join([f"namespace {namespace!r}: {len(est)} confirmed tracks (model {model}, latest estimate of each)",
                      fmt(head), *map(fmt, rows)])
