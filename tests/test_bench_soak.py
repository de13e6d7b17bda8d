"""The soak's figures (bench.soak.soak_figures) from its samples."""

from __future__ import annotations

import pytest

from bench.soak import sample_line, soak_figures


def _samples(rss: list[float], queued: list[int] | None = None) -> list[dict]:
    return [{"t_s": 10.0 * k, "rss_mb": r, "anon_mb": r - 100.0, "file_mb": 100.0,
             "queued": None if queued is None else queued[k]} for k, r in enumerate(rss)]


def test_first_minute_left_out_of_the_spread_and_slope() -> None:
    rss = [300, 400, 500, 600, 650, 660, 600, 660, 600, 660, 600, 660]  # t = 0..110 s; from 60 s a saw-tooth
    f = soak_figures(_samples(rss, queued=[0] * 6 + [0, 5, 0, 9000, 0, 0]))
    assert f["rss_start_mb"] == 300 and f["rss_min_mb"] == 300 and f["rss_max_mb"] == 660
    assert f["rss_min_after_1min_mb"] == 600 and f["rss_max_after_1min_mb"] == 660
    assert f["spread_after_1min"] == pytest.approx(0.1)
    assert f["anon_spread_after_1min"] == pytest.approx(560 / 500 - 1)
    assert f["slope_mb_per_min"] > 100 and f["slope_after_1min_mb_per_min"] == pytest.approx(90 / 17.5 * 6)  # 30.9
    assert f["queued_max_after_1min"] == 9000


def test_a_short_soak_uses_every_sample() -> None:
    f = soak_figures(_samples([300, 330, 360]))
    assert f["spread_after_1min"] == pytest.approx(0.2) and f["slope_after_1min_mb_per_min"] == pytest.approx(180)
    assert f["queued_max_after_1min"] is None


def test_a_sample_prints_on_one_line_as_it_comes() -> None:
    s = _samples([437.0])[0] | {"applied": 600318, "queued": 0}
    assert sample_line(s) == "  t=    0 s  rss    437.0 MB (anon   337.0, file  100.0)  queued 0  applied 600318"
