"""The Kalman gain of a viewed track, split by the unit of the measured component it multiplies.

K = P- H' S^-1 is (n x m): column j turns the innovation's component j into a state correction,
so its unit is [state unit / unit of z_j]. A radar's bearing column is in m/rad and is ~range
times larger than its range column (m/m): drawn in one panel, the range gains are a flat line.
So the gain goes to one entity per (group of measured unit, sensor), and one view per group:
  m     lengths (Cartesian axes, range):  K[x, range] in m/m, K[vx, range] in 1/s
  rad   angles (bearing, azimuth, elevation): m/rad and m/s/rad
  m/s   range rate: s and 1
  1     components of unknown unit (a custom model's non-angle components, or a recording whose
        sink was given no `measured` description): one unsplit view, as before.

`measured_components` describes each sensor's components as (name, unit), per measurement model
of the sensor, for the recording's meta (key "measured"); the sink reads them back from there.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

# unit of the measured component -> (entity below tracks/<label>/gain, view title)
GROUPS: dict[str, tuple[str, str]] = {
    "m": ("per_m", "Kalman gain per m measured [m/m, 1/s]"),
    "rad": ("per_rad", "Kalman gain per rad measured [m/rad, m/s/rad]"),
    "m/s": ("per_m_s", "Kalman gain per m/s measured [s, 1]"),
    "1": ("other", "Kalman gain"),
}


def measured_components(sensors: Mapping[str, Any], layout: Sequence[str]) -> dict[str, list[list[list[str]]]]:
    """sensor id -> one description per measurement model of the sensor (fusion.tracking.models
    .SensorModel.by_dim, by dimension m): [[name, unit], ...] of its m components, in z order."""
    return {sid: [_components(sensors[sid].by_dim[m], layout) for m in sorted(sensors[sid].by_dim)]
            for sid in sorted(sensors)}


def _components(model: Any, layout: Sequence[str]) -> list[list[str]]:
    """Cartesian sensors measure the layout's position components (in the sensor's frame when it
    has a pose), radars range (m), their angles (rad) and optionally range rate (m/s); other
    models name their components z0, z1, ... with unit rad for their angle_indices, else 1."""
    from fusion.core.measurement import CartesianPosition
    from fusion.core.radar import Radar2D, Radar3D

    if isinstance(model, CartesianPosition):
        return [[str(layout[i]), "m"] for i in model.indices]
    if isinstance(model, Radar2D | Radar3D):
        angles = ["bearing"] if isinstance(model, Radar2D) else ["azimuth", "elevation"]
        comps = [["range", "m"]] + [[a, "rad"] for a in angles]
        return comps + ([["range rate", "m/s"]] if model.range_rate else [])
    ang = set(getattr(model, "angle_indices", ()))
    return [[f"z{j}", "rad" if j in ang else "1"] for j in range(int(model.ndim_meas))]


def split(measured: Mapping[str, Sequence[Sequence[Sequence[str]]]], sensor: str,
          m: int) -> list[tuple[str, list[int], list[str]]]:
    """(group entity, column indices, component names) of a sensor's m gain columns, in GROUPS
    order; a sensor not described with m components is one group of unit 1, named 0..m-1."""
    comps = next((c for c in measured.get(sensor, ()) if len(c) == m), None)
    if comps is None or any(c[1] not in GROUPS for c in comps):
        return [(GROUPS["1"][0], list(range(m)), [str(j) for j in range(m)])]
    out = []
    for unit, (entity, _) in GROUPS.items():
        cols = [j for j, c in enumerate(comps) if c[1] == unit]
        if cols:
            out.append((entity, cols, [str(comps[j][0]) for j in cols]))
    return out
