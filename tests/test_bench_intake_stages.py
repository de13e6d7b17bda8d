"""bench.intake_stages drives the service's own code with stubs in its place (a stubbed tracker,
a dummy session, the pipeline's output replayed): a change of those signatures must break this
test, not the benchmark the next time someone runs it (f4d1c30's ingest(prune=...) did)."""

from __future__ import annotations

import math
from pathlib import Path

from bench.intake_stages import STAGES, _child

REPO = Path(__file__).resolve().parents[1]


def test_every_stage_runs_on_a_small_load() -> None:
    out = _child(str(REPO), 3, 1.0, 1)
    assert out["measurements"] == 45  # 3 targets x 15 measurements per second x 1 s
    assert out["published"] > 0
    for stage in STAGES:
        assert math.isfinite(out[stage]) and out[stage] > 0, stage
