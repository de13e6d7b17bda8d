"""Scenario and simulated-sensor descriptions, loaded from TOML (configs/scenarios/*.toml)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import msgspec

from fusion.config import ServiceConfig
from fusion.config_errors import convert, decode_toml
from fusion.errors import ConfigError

Prob = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
NonNeg = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Pos = Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]


class Spec(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    pass


class LatencySpec(Spec, kw_only=True):
    """Arrival time = sensor time + base_ms + a gamma-distributed jitter of mean jitter_ms.
    Any jitter makes arrivals out of order; jitter_ms = 0 keeps sensor-time order."""

    base_ms: NonNeg = 0.0
    jitter_ms: NonNeg = 0.0
    shape: Pos = 2.0


class SensorSpec(Spec, kw_only=True):
    """A simulated sensor. kind "cartesian": std_m per axis. kind "radar": range and bearing
    (elevation in 3-D, range rate if range_rate) relative to position_m and heading_rad.
    rate_hz None measures at every truth sample; otherwise at the samples closest to that rate."""

    id: str
    kind: Literal["cartesian", "radar"]
    position_m: list[float] = []
    heading_rad: float = 0.0
    rate_hz: Pos | None = None
    std_m: list[Pos] = []
    range_std_m: Pos = 1.0
    bearing_std_rad: Pos = 0.01
    elevation_std_rad: Pos = 0.01
    range_rate: bool = False
    range_rate_std_mps: Pos = 0.5
    latency: LatencySpec = LatencySpec()
    dropout: Prob = 0.0  # probability a message is lost on the way
    pd: Prob = 1.0  # detection probability
    clutter_per_scan: NonNeg = 0.0  # Poisson mean of false alarms per scan
    clutter_region_m: list[float] = []  # [xmin, xmax, ymin, ymax(, zmin, zmax)]
    duplicate: Prob = 0.0  # probability a message is sent twice


class ScenarioSpec(Spec, kw_only=True):
    """What the publishers stream. source: a reference scenario of fusion.scenarios
    (its own measurements; `sensors` may give one entry to set latency and drop-outs) or
    "mix" (targets of publishers.mix seen by every sensor in `sensors`)."""

    source: str
    seed: int = 0
    duration_s: Pos | None = None
    targets: Annotated[int, msgspec.Meta(ge=1, le=100_000)] = 5
    dt_s: Pos = 0.1
    sensors: list[SensorSpec] = []


class ScenarioFile(Spec, kw_only=True):
    """A scenario file: what to stream, and how the service should track it."""

    scenario: ScenarioSpec
    service: ServiceConfig


def load_scenario_file(path: str | Path) -> ScenarioFile:
    """Read a scenario file; errors name the file, line and field (fusion.config_errors)."""
    data = Path(path).read_bytes()
    return convert(decode_toml(data, source=str(path)), ScenarioFile, source=str(path), text=data)


CONFIG_DIR = Path(__file__).resolve().parent.parent / "configs" / "scenarios"


def scenario_path(name: str) -> Path:
    """configs/scenarios/<name>.toml of this checkout."""
    p = CONFIG_DIR / f"{name}.toml"
    if not p.exists():
        known = ", ".join(sorted(q.stem for q in CONFIG_DIR.glob("*.toml")))
        raise ConfigError(f"no scenario {name!r}; known: {known}")
    return p
