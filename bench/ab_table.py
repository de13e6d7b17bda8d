"""The table an interleaved A/B over the real service prints (bench.recording_ab, bench.tree_ab):
per figure, the median (min-max) of each variant and the ratio new/old per pair.

`rows`: one dict per run: "variant", "pair", and the runs' results under "lat10000", "lat1000"
(bench.service_e2e.latency_run) and "throughput" (throughput_run, 1000 targets), "throughput100"
(100 targets); a figure no run has is left out of the table."""

from __future__ import annotations

from typing import Any

import numpy as np

FIGURES = [("10k/s p50 ms", "lat10000", "p50_ms"), ("10k/s p99 ms", "lat10000", "p99_ms"),
           ("10k/s max ms", "lat10000", "max_ms"), ("1k/s p50 ms", "lat1000", "p50_ms"),
           ("1k/s p99 ms", "lat1000", "p99_ms"), ("1k/s max ms", "lat1000", "max_ms"),
           ("blast at 100 targets, k/s", "throughput100", "rate"), ("blast at 1000 targets, k/s", "throughput", "rate")]


def value(row: dict[str, Any], run_key: str, key: str) -> float | None:
    """A figure of one run (a throughput in k/s); None where the run did not measure it."""
    v = row[run_key].get(key) if run_key in row else None
    return None if v is None else v / 1e3 if key == "rate" else v


def spread(xs: list[float]) -> str:
    return f"{np.median(xs):.1f} ({min(xs):.1f}-{max(xs):.1f})" if xs else "-"


def print_ab(rows: list[dict[str, Any]], *, new: str, old: str, new_header: str, old_header: str) -> None:
    print(f"\n| figure | {new_header}, median (min-max) | {old_header} | {new}/{old} per pair |\n|---|---|---|---|")
    for label, run_key, key in FIGURES:
        by: dict[str, dict[int, float]] = {new: {}, old: {}}
        for r in rows:
            v = value(r, run_key, key)
            if v is not None:
                by[r["variant"]][r["pair"]] = v
        if not by[new] and not by[old]:
            continue
        ratios = [by[new][k] / by[old][k] for k in sorted(by[new]) if k in by[old] and by[old][k]]
        print(f"| {label} | {spread(list(by[new].values()))} | {spread(list(by[old].values()))} | "
              + (", ".join(f"{x:.2f}" for x in ratios) or "-") + " |")
