"""The stored blueprint of a recording of every reference scenario (and the mix) shows data in
every view: the queries are read back from the .rrd and evaluated with Rerun's rules
(tests/io/blueprint_check.py). On main's sink before this change, four of its six views selected
nothing (`$origin/*/state`-style queries); test_old_style_queries_select_nothing keeps that fact."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.io.blueprint_check import View, data_entities, empty_views, last_blueprint_views, selects
from tests.io.scenario_run import record_scenario

SCENARIOS = sorted(p.stem for p in (Path(__file__).resolve().parents[2] / "configs" / "scenarios").glob("*.toml"))
NEEDED = ("over time", "error", "NIS, 95 % bounds", "NEES, 95 % bounds", "sqrt(diag P)", "Kalman gain")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("scenarios")
    out = {}
    for name in SCENARIOS:
        out[name] = d / f"{name}.rrd"
        record_scenario(name, out[name], duration_s=20.0 if name == "mix" else None)
    return out


@pytest.mark.parametrize("name", SCENARIOS, ids=SCENARIOS)
def test_every_view_selects_data(recordings: dict[str, Path], name: str) -> None:
    path = recordings[name]
    views = last_blueprint_views(path)
    assert len(views) >= 8, [v.name for v in views]
    assert empty_views(path) == []
    names = [v.name for v in views]
    for role in NEEDED:  # every scenario has truth: each role has its view for the viewed tracks
        assert any(role in n for n in names), (role, names)
    if name == "mix":
        assert any("IMM mode probabilities" in n for n in names)
    kinds = {v.kind for v in views}
    assert "TimeSeries" in kinds and "TextLog" in kinds
    assert ("3D" in kinds) == (not name.startswith("cv1d"))  # cv1d as time series, the rest as 3-D scenes


def test_old_style_queries_select_nothing(recordings: dict[str, Path]) -> None:
    """The evaluator follows Rerun: a `*` inside a path is no wildcard (main's blueprint relied on it)."""
    data = data_entities(recordings["radar2d"])
    old = View("State", "TimeSeries", "/tracks", ["$origin/*/std"])
    assert not any(selects(old, e) for e in data)
    new = View("std", "TimeSeries", "/tracks", ["$origin/**"])
    assert any(selects(new, e) and e.endswith("/std") for e in data)


@pytest.mark.parametrize(("query", "entity", "expected"), [
    (["/world/**", "- /world/car/**", "+ /world/car/driver"], "/world/car/driver", True),
    (["/world/**", "- /world/car/**", "+ /world/car/driver"], "/world/car/hood", False),
    (["/world/**", "- /world"], "/world", False),
    (["/world/**", "- /world"], "/world/house", True),
    (["$origin/**"], "/worldwide", False),
], ids=["exact-beats-subtree", "excluded-subtree", "exact-exclusion", "subtree", "prefix-is-not-child"])
def test_query_rules_as_documented(query: list[str], entity: str, expected: bool) -> None:
    assert selects(View("v", "3D", "/world", query), entity) is expected


def test_the_cursor_view_shows_now_the_trajectory_view_history(recordings: dict[str, Path]) -> None:
    """"at the cursor": each viewed track's estimate and ellipse, and the truth, but no start
    markers or trail (at the end of a run a start marker sat 60 m from its track, in the truth's
    green: read as the target the track had lost); the trajectory view keeps both."""
    from fusion.io.palette import colour

    data = data_entities(recordings["mix"])
    views = {v.name: v for v in last_blueprint_views(recordings["mix"])}
    cursor = views["at the cursor (2-sigma ellipses)"]
    path = next(v for n, v in views.items() if n.startswith("trajectories up to the cursor"))
    starts = [e for e in data if e.startswith("/world/tracks/") and e.endswith("/start")]
    nows = [e for e in data if e.startswith("/world/tracks/") and e.endswith("/now")]
    assert starts and nows
    assert not any(selects(cursor, e) for e in starts) and all(selects(cursor, e) for e in nows)
    assert selects(cursor, "/world/truth")
    assert all(selects(path, e) for e in starts)
    marks = ("start", "end", "estimate", "associated", "measurement", "prediction")
    assert colour("truth") not in [colour(r) for r in marks]
