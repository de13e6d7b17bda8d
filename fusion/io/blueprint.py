"""The layout a reviewer sees when opening a recording: which views, and what each one selects.

Rerun's entity queries match a path exactly, or a whole subtree with a trailing `/**`; no other
wildcard exists (a `*` inside a path matches nothing, silently). So every view here has an origin
at the subtree of one role and the query `$origin/**` (plus explicit `- path` exclusions), and a
view is only laid out once an entity under its origin holds data (`written`): no empty panels.

Layout: left, the trajectories (a 3-D view looking down the z axis with y up for 2-D data, a
free 3-D view for 3-D data, a time series of position for 1-D data) over tabs with the events,
the association outcomes, OSPA/GOSPA and the counts; right, one tab per viewed track with its
time series: position per axis (estimate, prediction, truth, measurements), error per axis with
its +-2 sigma band, NIS and NEES with their 95 % chi-square bounds, sqrt(diag P), the Kalman gain,
the innovation with +-2 sqrt(diag S), IMM mode probabilities; the smoothed estimate, error and
sigma of `fusion replay --smooth` (fusion.io.smoothed, logged after the last blueprint) appear in
the position, error and sqrt(diag P) views, as entities inside their subtrees. The Kalman gain has
one view per unit of the measured components (fusion.io.gain_groups): a radar's bearing gain
(m/rad, ~range times its range gain) gets its own scale.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from fusion.io.gain_groups import GROUPS

# (subtree under tracks/<label>, view title): the per-track views, in display order
TRACK_VIEWS: tuple[tuple[str, str], ...] = (
    ("position/{axis}", "{axis} over time"),
    ("error/{axis}", "error {axis} +-2 sigma"),
    ("nis", "NIS, 95 % bounds"),
    ("nees", "NEES, 95 % bounds"),
    ("std", "sqrt(diag P)"),
    *((f"gain/{entity}", title) for entity, title in GROUPS.values()),  # one scale per measured unit
    ("innovation", "innovation +-2 sqrt(diag S)"),
    ("mode", "IMM mode probabilities"),
)  # the smoothed series (fusion.io.smoothed) sit inside the position, error and std subtrees


def _has_data(origin: str, written: Iterable[str]) -> bool:
    o = "/" + origin.strip("/")
    return any(w == o or w.startswith(o + "/") for w in written)


def track_views(label: str, axes: Sequence[str], written: set[str]) -> list[tuple[str, str]]:
    """(origin, title) of the views of one track whose subtree holds data."""
    out = []
    for sub, title in TRACK_VIEWS:
        for axis in axes if "{axis}" in sub else ("",):
            origin = f"tracks/{label}/" + sub.format(axis=axis)
            if _has_data(origin, written):
                out.append((origin, f"{label} " + title.format(axis=axis)))
    return out


def layout_key(*, viewed: Sequence[str], axes: Sequence[str], written: set[str]) -> tuple:
    """What the layout depends on: the viewed tracks, their views with data, the optional tabs."""
    views = tuple(o for lab in viewed for o, _ in track_views(lab, axes, written))
    return (tuple(viewed), views, _has_data("metrics", written), _has_data("counts", written))


def build(*, ndim: int, axes: Sequence[str], viewed: Sequence[str], written: set[str],
          centre: Sequence[float], extent_m: float) -> Any:
    """The blueprint. `viewed`: labels of the tracks with their own views (in tab order);
    `written`: entity paths holding data; `centre`, `extent_m`: the scene, for the top-down eye."""
    import rerun.blueprint as rrb

    legend = rrb.PlotLegend(visible=True)
    history = rrb.VisibleTimeRange("t", start=rrb.TimeRangeBoundary.infinite(),
                                   end=rrb.TimeRangeBoundary.cursor_relative())
    left: list[Any] = []
    if ndim == 1:
        contents = [f"/tracks/{lab}/position/{axes[0]}/**" for lab in viewed] or ["/tracks/**"]
        left.append(rrb.TimeSeriesView(origin="/", contents=contents, name="position over time, viewed tracks",
                                       plot_legend=legend))
    else:
        eye = None
        if ndim == 2:  # top-down: y up on the screen, looking along -z
            cx, cy = float(centre[0]), float(centre[1])
            eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=(cx, cy, 3.0 * extent_m + 1.0),
                                    look_target=(cx, cy, 0.0), eye_up=(0.0, 1.0, 0.0))
        cursor_only = [f"- /world/tracks/{lab}/{part}" for lab in viewed for part in ("cov", "now")]
        left.append(rrb.Spatial3DView(origin="world", contents=["$origin/**", *cursor_only],
                                      name="trajectories up to the cursor (faint: earlier 2-sigma ellipses)",
                                      time_ranges=history, eye_controls=eye,
                                      line_grid=rrb.LineGrid3D(visible=ndim == 3)))
        # earlier ellipses and the start markers: the trajectory view's (at the cursor, a start marker
        # far from the track read as a target the track had lost)
        trails = [f"- /world/tracks/{lab}/{part}" for lab in viewed for part in ("trail", "start")]
        left.append(rrb.Spatial3DView(origin="world", contents=["$origin/**", *trails],
                                      name="at the cursor (2-sigma ellipses)",
                                      eye_controls=eye, line_grid=rrb.LineGrid3D(visible=ndim == 3)))
    tabs: list[Any] = [rrb.TextLogView(origin="events", name="events")]
    if _has_data("metrics", written):
        tabs.append(rrb.TimeSeriesView(origin="metrics", name="OSPA / GOSPA vs truth [m]", plot_legend=legend))
    if _has_data("counts", written):
        tabs.append(rrb.TimeSeriesView(origin="counts", name="counts", plot_legend=legend))
    left.append(rrb.Tabs(*tabs))
    right = []
    for lab in viewed:
        views = [rrb.TimeSeriesView(origin=o, name=n, plot_legend=legend) for o, n in track_views(lab, axes, written)]
        if views:
            right.append(rrb.Grid(*views, name=f"track {lab}", grid_columns=2))
    shares = [3, 3, 1] if len(left) == 3 else [3, 1]
    root = rrb.Vertical(*left, row_shares=shares)
    if right:
        root = rrb.Horizontal(root, rrb.Tabs(*right), column_shares=[1, 1])
    return rrb.Blueprint(root, collapse_panels=True)
