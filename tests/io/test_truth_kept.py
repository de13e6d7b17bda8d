"""The recording keeps the truth it scores against only from the tracker's horizon on (or from the
oldest estimate still waiting for its time's truth): a service fed truth for hours held every
sample until fusion.io.truth_table.KEPT times (~170 bytes a sample then, ~1.1 MB a second at 667 targets and 10 Hz).
Dropping it changes nothing in the file: the same rows as a sink that keeps all of it, for the
mix scenario with measurements 1.9 s late (replays revise estimates back to the window's edge)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fusion.io.track_rows import Rows
from tests.io.recording_digest import digest
from tests.io.scenario_run import record_scenario


def _record(path: Path) -> None:
    """mix, every 40th measurement 1.9 s late (inside the 2 s window: estimates revised back there)."""
    record_scenario("mix", path, duration_s=20.0, late=(40, 1.9), flush_rows=300, flush_interval_s=1e9,
                    view_interval_s=1e9)


def test_truth_before_the_horizon_is_dropped_and_changes_nothing(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    kept: list[int] = []
    logged: set[int] = set()
    add, forget = Rows.add_truths, Rows.forget_truth_before

    def adding(self: Rows, target_ids: list[str], t_ns: list[int], S: np.ndarray) -> None:
        logged.update(t_ns)
        add(self, target_ids, t_ns, S)

    def forgetting(self: Rows, t_ns: int) -> None:
        forget(self, t_ns)
        kept.append(len(self.truth))

    monkeypatch.setattr(Rows, "add_truths", adding)
    monkeypatch.setattr(Rows, "forget_truth_before", forgetting)
    _record(tmp_path / "dropped.rrd")
    assert len(kept) >= 20, "too few flushes with a horizon: no test"
    # the window (2 s) and the wait for a time's truth: about 4 s of radar scans (10 Hz) at most
    assert max(kept) <= 60 and len(logged) >= 150, (max(kept), len(logged))

    monkeypatch.setattr(Rows, "forget_truth_before", lambda self, t_ns: None)  # keep all of it
    _record(tmp_path / "kept.rrd")
    assert digest(tmp_path / "dropped.rrd") == digest(tmp_path / "kept.rrd")
