"""Interleaved A/B of two versions of the code: the working tree against a git revision (a
detached worktree of it, made for the run and removed after), both the real `fusion serve` of
bench.service_e2e with the shipped configuration (each tree's own configs/service.toml,
recording on), a fresh service for every run, alternating A, B, B, A... The service runs from
one tree or the other by PYTHONPATH (the benchmark's own code, the publisher and the client, is
the working tree's).

Per pair: publish-to-estimate latency at 10k measurements/s offered (667 targets) and at 1k/s (67
targets) over `duration_s` (20 s by default: a view flush, every 15 s, falls inside), and the
blast throughput at 100 and at 1000 targets (bench.service_e2e.throughput_run; at 100 targets a
scan is ten times smaller, so what a scan or a step costs weighs more). Printed: each run, then the
median and range of each figure per version and the ratio tree/base per pair.

    python -m bench --only tree_ab --base HEAD [--pairs 4]
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from bench import e2e_procs
from bench.ab_table import FIGURES, print_ab, value
from bench.e2e_procs import Publisher
from bench.service_e2e import latency_run, throughput_run

ROOT = Path(__file__).resolve().parent.parent
@contextmanager
def worktree(rev: str):
    """A detached worktree of `rev` (its commit id and path), removed afterwards."""
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True, capture_output=True,
                            text=True).stdout.strip()
    with tempfile.TemporaryDirectory(prefix="fusion-base-") as d:
        path = Path(d) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", "-q", str(path), commit], cwd=ROOT, check=True)
        try:
            yield commit, path
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(path)], cwd=ROOT, check=False)


@contextmanager
def code_of(tree: Path):
    """`fusion serve` started inside the block runs the code of `tree` with the shipped
    configuration of `tree` (its configs/service.toml: a tree's settings are part of it)."""
    old, old_config = os.environ.get("PYTHONPATH"), e2e_procs.CONFIG
    os.environ["PYTHONPATH"] = str(tree)
    e2e_procs.CONFIG = tree / "configs" / "service.toml"
    try:
        yield
    finally:
        e2e_procs.CONFIG = old_config
        if old is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = old


def run(*, base: str = "HEAD", pairs: int = 4, duration_s: float = 20.0, quick: bool = False) -> dict[str, Any]:
    if quick:
        pairs, duration_s = 1, 6.0
    rows: list[dict[str, Any]] = []
    with worktree(base) as (commit, base_tree), tempfile.TemporaryDirectory(prefix="fusion-tree-ab-") as d, \
            Publisher() as pub, Publisher() as pub100:
        trees = {"base": base_tree, "tree": ROOT}
        print(f"tree A/B: the working tree against {base} ({commit}), {pairs} interleaved pairs, recording on; "
              f"load average {os.getloadavg()}", flush=True)
        tmp = Path(d)
        n = 150_000
        pub.call("prepare", {"targets": 1000, "messages": n, "seed": 1000}, timeout_s=300.0)
        pub100.call("prepare", {"targets": 100, "messages": n, "seed": 100}, timeout_s=300.0)
        for k in range(pairs):
            for name in (("base", "tree") if k % 2 == 0 else ("tree", "base")):
                row: dict[str, Any] = {"variant": name, "pair": k}
                with code_of(trees[name]):
                    for rate in (10_000, 1_000):
                        row[f"lat{rate}"] = latency_run(pub, tmp / f"lat-{rate}-{name}-{k}", rate=rate, recording=True,
                                                        duration_s=duration_s, grace_s=3.0)
                    row["throughput100"] = throughput_run(pub100, tmp / f"tp100-{name}-{k}", n=n, targets=100,
                                                          recording=True, window_s=5.0, warm_deadline_s=60.0,
                                                          after_warm_s=40.0)
                    row["throughput"] = throughput_run(pub, tmp / f"tp-{name}-{k}", n=n, targets=1000, recording=True,
                                                       window_s=5.0, warm_deadline_s=60.0, after_warm_s=40.0)
                rows.append(row)
                print(f"  pair {k} {name:4s}: " + ", ".join(f"{label} {_value(row, run_key, key)}"
                                                            for label, run_key, key in FIGURES), flush=True)
    print_ab(rows, new="tree", old="base", new_header="working tree", old_header=f"{base} ({commit})")
    return {"base": base, "commit": commit, "rows": rows, "loadavg_end": os.getloadavg()}


def _value(row: dict[str, Any], run_key: str, key: str) -> str:
    v = value(row, run_key, key)
    return "n/a" if v is None else f"{v:.1f}"
