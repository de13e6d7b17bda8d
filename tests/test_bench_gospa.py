"""bench/gospa.py on a tiny case, so the benchmark's code cannot rot (Stone Soup needed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("stonesoup")

from bench import gospa  # noqa: E402


@pytest.mark.parametrize("kind", ["cartesian", "radar"])
def test_both_trackers_are_scored_on_the_same_scans(kind: str) -> None:
    fusion, stonesoup = gospa.compare(kind, "light", seed=0, duration_s=3.0)
    assert len(fusion.parts) == len(stonesoup.parts) == 7  # a scan every 0.5 s over 3 s
    for run in (fusion, stonesoup):
        assert len(run.step_s) == len(run.parts) and min(run.step_s) > 0
        for g in run.parts:
            assert g.distance == pytest.approx(math.sqrt(g.localisation + g.missed + g.false), rel=1e-12)
        first, last = run.parts[0], run.parts[-1]
        assert first.n_missed == 10 - 0 and first.n_false == 0, "nothing is confirmed at the first scan"
        assert last.n_missed <= 2 and last.n_false <= 1, "3 of 5 confirms the targets within 3 s"
        assert last.localisation / (10 - last.n_missed) < (3 * 5.0) ** 2  # within 3 sigma of the truth


def test_a_setting_prints_and_returns_its_figures(capsys: pytest.CaptureFixture[str]) -> None:
    res = gospa.setting("cartesian", "heavy", range(2), 2.0)
    out = capsys.readouterr().out
    assert out.count("cartesian/heavy") == 3
    for who in ("fusion", "stonesoup"):
        assert np.isfinite(res[f"cartesian/heavy/{who}/gospa_m"]) and res[f"cartesian/heavy/{who}/ms_per_scan"] > 0
    assert res["cartesian/heavy/fusion_at_or_below"] in (0, 1, 2)
    assert res["cartesian/heavy/speed_ratio"] > 0
