"""Scenario and simulated-sensor descriptions, loaded from TOML (configs/scenarios/*.toml)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import msgspec

from fusion.config import CartesianSensorConfig, RadarSensorConfig, ServiceConfig
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


class SimulatedCartesian(CartesianSensorConfig, tag="cartesian"):
    """A simulated position sensor: the service's sensor configuration (id, pose, noise) plus
    how it is simulated. rate_hz None measures at every truth sample; otherwise at the samples
    closest to that rate."""

    rate_hz: Pos | None = None
    latency: LatencySpec = LatencySpec()
    dropout: Prob = 0.0  # probability a message is lost on the way
    pd: Prob = 1.0  # detection probability
    clutter_per_scan: NonNeg = 0.0  # Poisson mean of false alarms per scan
    clutter_region_m: list[float] = msgspec.field(default_factory=list)  # [xmin, xmax, ymin, ymax(, zmin, zmax)]
    duplicate: Prob = 0.0  # probability a message is sent twice

    def __post_init__(self) -> None:
        if self.std_m is None:
            raise ValueError(f"simulated sensor {self.id}: std_m is needed to simulate its noise")


class SimulatedRadar(RadarSensorConfig, tag="radar"):
    """A simulated radar: the service's sensor configuration (id, pose, noise) plus how it is
    simulated (as SimulatedCartesian; range_rate: whether returns carry a range rate)."""

    rate_hz: Pos | None = None
    range_rate: bool = False
    latency: LatencySpec = LatencySpec()
    dropout: Prob = 0.0
    pd: Prob = 1.0
    clutter_per_scan: NonNeg = 0.0
    clutter_region_m: list[float] = msgspec.field(default_factory=list)
    duplicate: Prob = 0.0

    def __post_init__(self) -> None:
        need = {"range_std_m": self.range_std_m, "bearing_std_rad": self.bearing_std_rad}
        if self.range_rate:
            need["range_rate_std_mps"] = self.range_rate_std_mps
        missing = [k for k, v in need.items() if v is None]
        if missing:
            raise ValueError(f"simulated radar {self.id}: {', '.join(missing)} needed to simulate its noise")


SensorSpec = SimulatedCartesian | SimulatedRadar


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
