"""What the review's views show beyond "every view selects data" (tests/io/test_blueprint.py):
the Kalman gain split by the unit of the measured components (a radar's bearing gain on its own
scale), the faint covariance trail of the trajectory view (decimated: no two ellipses overlap),
and the smoothed series of `fusion replay --smooth` inside the filtered track's views."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rerun.chunk import RrdReader

from fusion.config import load_service_config
from fusion.io import derive, gain_groups, trail
from fusion.replay import replay
from fusion.tracking.tracker import Tracker
from tests.io.blueprint_check import data_entities, empty_views, last_blueprint_views, selects
from tests.io.scenario_run import record_scenario, write_scenario_stream

SCENARIOS = Path(__file__).resolve().parents[2] / "configs" / "scenarios"


def _rows(path: Path, suffix: str, component: str = "Scalars:scalars") -> dict[str, list]:
    """entity -> its temporal rows of `component` (as Python lists), for entities ending in suffix."""
    out: dict[str, list] = {}
    for ch in RrdReader(str(path)).stream():
        if ch.is_static or not ch.entity_path.endswith(suffix):
            continue
        b = ch.to_record_batch()
        if component in b.schema.names:
            out.setdefault(ch.entity_path, []).extend(b.column(component).to_pylist())
    return out


@pytest.fixture(scope="module")
def radar(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("radar") / "radar2d.rrd"
    record_scenario("radar2d", path)
    return path


def test_measured_components_name_units_per_model() -> None:
    tr = Tracker(load_service_config(SCENARIOS / "mix.toml").tracker)
    got = gain_groups.measured_components(tr.sensors, tr.layout)
    assert sorted(got) == sorted(tr.sensors)
    descs = [d for per_sensor in got.values() for d in per_sensor]
    assert [["range", "m"], ["bearing", "rad"]] in descs
    assert [["x", "m"], ["y", "m"]] in descs


@pytest.mark.parametrize(("measured", "m", "expected"), [
    ({"r": [[["range", "m"], ["bearing", "rad"]]]}, 2, [("per_m", [0], ["range"]), ("per_rad", [1], ["bearing"])]),
    ({"r": [[["range", "m"], ["bearing", "rad"], ["range rate", "m/s"]]]}, 3,
     [("per_m", [0], ["range"]), ("per_rad", [1], ["bearing"]), ("per_m_s", [2], ["range rate"])]),
    ({"r": [[["range", "m"], ["bearing", "rad"]]]}, 3, [("other", [0, 1, 2], ["0", "1", "2"])]),
    ({}, 2, [("other", [0, 1], ["0", "1"])]),
    ({"r": [[["a", "furlong"], ["b", "m"]]]}, 2, [("other", [0, 1], ["0", "1"])]),
], ids=["radar", "radar-with-rate", "other-dimension", "undescribed", "unknown-unit"])
def test_split_groups_columns_by_unit(measured: dict, m: int, expected: list) -> None:
    assert gain_groups.split(measured, "r", m) == expected


def test_radar_gain_has_one_scale_per_unit(radar: Path) -> None:
    """The bearing gain (m/rad) is hundreds of times the range gain (m/m): apart, both are readable."""
    rows = _rows(radar, "/radar")
    per_m = [e for e in rows if "/gain/per_m/" in e]
    per_rad = [e for e in rows if "/gain/per_rad/" in e]
    assert len(per_m) == len(per_rad) == 1, sorted(rows)
    big = np.nanmax(np.abs(np.array(rows[per_rad[0]])))
    small = np.nanmax(np.abs(np.array(rows[per_m[0]])))
    assert big > 100 * small, (big, small)  # measured: 632 m/rad against 0.68 (1/s)
    views = {v.name: v for v in last_blueprint_views(radar)}
    for entity, title in ((per_m[0], "per m measured"), (per_rad[0], "per rad measured")):
        (v,) = [v for n, v in views.items() if title in n]
        assert selects(v, entity)
        assert not any(selects(v, other) for other in (per_m + per_rad) if other != entity)


@pytest.mark.parametrize(("t", "pos", "r", "last", "expected"), [
    ([0, 1, 2, 3], [[0, 0], [1, 0], [3, 0], [5, 0]], [1.0] * 4, None, [0, 2]),  # 2.5 m apart at least
    ([0, 1, 2], [[0, 0], [10, 0], [20, 0]], [1.0] * 3, None, [0, 1, 2]),
    ([5, 6], [[10, 0], [20, 0]], [1.0, 1.0], (7, np.array([0.0, 0.0]), 1.0), []),  # older than the last drawn
    ([0, 1, 2], [[0, 0], [0, 0], [0, 0]], [1.0] * 3, None, [0]),  # stationary: one
], ids=["spaced", "fast", "revisions", "stationary"])
def test_trail_pick(t: list, pos: list, r: list, last: tuple | None, expected: list[int]) -> None:
    got, new_last = trail.pick(np.array(t), np.array(pos, float), np.array(r), last)
    assert got == expected
    if expected:
        assert new_last is not None and new_last[0] == t[expected[-1]]


def test_trail_radii_are_two_sigma_of_the_largest_axis() -> None:
    P = np.array([[[4.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 9.0]]])
    np.testing.assert_allclose(trail.radii(P), [4.0, 6.0])


@pytest.mark.parametrize("scenario", ["radar2d", "maneuver2d"], ids=str)
def test_trail_ellipses_are_few_and_apart(scenario: str, radar: Path, tmp_path: Path) -> None:
    path = radar
    if scenario != "radar2d":
        path = tmp_path / f"{scenario}.rrd"
        record_scenario(scenario, path)
    trails = _rows(path, "/trail", "LineStrips3D:strips")
    covs = _rows(path, "/cov", "LineStrips3D:strips")
    assert trails, sorted(covs)
    for entity, strips in trails.items():
        n_cov = len(covs[entity.replace("/trail", "/cov")])
        assert 3 <= len(strips) < 0.6 * n_cov, (len(strips), n_cov)
        pts = [np.array(s[0], dtype=float)[:, :2] for s in strips]  # one closed outline per row
        centres = [p[:-1].mean(axis=0) for p in pts]
        radius = [np.max(np.linalg.norm(p - c, axis=1)) for p, c in zip(pts, centres, strict=True)]
        for i in range(1, len(pts)):  # neighbours' bounding circles do not touch: no rope
            assert np.linalg.norm(centres[i] - centres[i - 1]) >= radius[i] + radius[i - 1], i
    views = {v.name: v for v in last_blueprint_views(path)}
    (traj,) = [v for n, v in views.items() if n.startswith("trajectories")]
    (cursor,) = [v for n, v in views.items() if n.startswith("at the cursor")]
    for entity in trails:
        assert selects(traj, entity) and not selects(cursor, entity)
        assert selects(cursor, entity.replace("/trail", "/cov")) and not selects(traj, entity.replace("/trail", "/cov"))


def test_smoothed_series_sit_in_the_filtered_views(tmp_path: Path) -> None:
    """`fusion replay --smooth` logs the smoothed tracks after the last blueprint: the position,
    error and sqrt(diag P) views of each viewed track select them."""
    stream = write_scenario_stream("radar2d", tmp_path / "radar2d.fstream")
    out = tmp_path / "smoothed.rrd"
    res = replay(stream, out=out, smooth=True)
    assert res.smoothed_tracks >= 1 and res.rmse_smoothed_m < res.rmse_filtered_m
    assert empty_views(out) == []
    data = data_entities(out)
    views = last_blueprint_views(out)
    labels = {v.name.split()[0] for v in views if v.name.endswith("over time")}
    assert labels
    for lab in sorted(labels):
        for entity, role in ((f"/tracks/{lab}/position/x/smoothed", "x over time"),
                             (f"/tracks/{lab}/position/y/smoothed", "y over time"),
                             (f"/tracks/{lab}/error/x/smoothed", "error x"),
                             (f"/tracks/{lab}/error/y/smoothed", "error y"),
                             (f"/tracks/{lab}/std/smoothed", "sqrt(diag P)")):
            assert entity in data, entity
            (v,) = [v for v in views if v.name == f"{lab} {role}" or v.name.startswith(f"{lab} {role} ")]
            assert selects(v, entity), (entity, v)
    err = _rows(out, "/error/x/smoothed")
    for rows in err.values():
        a = np.array(rows)
        assert a.shape[1] == 3 and np.all(a[:, 1] > 0) and np.allclose(a[:, 2], -a[:, 1])


def test_measurement_points_let_the_estimate_line_show(radar: Path) -> None:
    """Rerun draws a plot's points over its lines: the measurement points must be translucent and
    smaller than the estimate line is wide, or they hide it (docs: fusion.io.track_rows)."""
    style: dict[str, dict[str, list]] = {}
    for ch in RrdReader(str(radar)).stream():
        if ch.is_static and "/position/" in ch.entity_path:
            b = ch.to_record_batch()
            style[ch.entity_path] = {n: b.column(n).to_pylist()[-1] for n in b.schema.names if ":" in n}
    meas = [e for e in style if e.endswith("/measurement")]
    assert meas, sorted(style)
    for e in meas:
        est = style[e.replace("/measurement", "/estimate")]
        (rgba,) = style[e]["SeriesPoints:colors"]
        (size,) = style[e]["SeriesPoints:marker_sizes"]
        assert (rgba & 0xFF) <= 80, hex(rgba)  # alpha (colours are packed 0xRRGGBBAA)
        assert est["SeriesLines:names"][-1] == "estimate", est  # drawn last among the lines: on top of them
        assert size < est["SeriesLines:widths"][-1] / 2, (size, est)
        assert (est["SeriesLines:colors"][-1] & 0xFF) == 255


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 1e6), st.floats(0.0, 1e6), st.floats(-1.0, 1.0))
def test_closed_form_eigenvalues_of_2x2_covariances_are_lapacks(sa: float, sc: float, rho: float) -> None:
    """derive.eig_sym2 (the ellipses' and trail radii's eigen-decomposition, in closed form) against
    numpy's eigh on covariances of every shape: round, elongated, rotated, singular; the larger
    eigenvector at the returned angle."""
    b = rho * np.sqrt(sa * sc)
    C = np.array([[sa, b], [b, sc]])
    lo, hi, phi = derive.eig_sym2(C[None])
    w = np.linalg.eigvalsh(C)
    scale = max(abs(w).max(), 1e-300)
    assert abs(lo[0] - w[0]) <= 1e-12 * scale and abs(hi[0] - w[1]) <= 1e-12 * scale
    v = np.array([np.cos(phi[0]), np.sin(phi[0])])
    assert np.linalg.norm(C @ v - hi[0] * v) <= 1e-9 * scale
