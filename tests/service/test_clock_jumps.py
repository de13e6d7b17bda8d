"""Clock jumps in one sensor's timestamps (issue #13): the sensor's clock leaps an hour ahead for
a few messages, later falls a minute behind for a few; through the service's pipeline (the code
`fusion serve` runs on every batch) those messages are refused with their reasons, the track
goes on with the same id, and the counts add up. The window follows a robust clock
(fusion.tracking.clock), so the leap does not make the real data after it "too late"."""

from __future__ import annotations

from fusion import messages as m
from fusion.config import load_service_config
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from tests.cli.helpers import SERVICE_TOML

T0 = 1_800_000_000 * 10**9  # an epoch time in ns
STEP = 100_000_000  # cam1 at 10 Hz


def _cam(seq: int, t_ns: int) -> bytes:
    return m.encode(m.Measurement(sensor_id="cam1", t_ns=t_ns, seq=seq,
                                  data=m.Cartesian(pos_m=[100.0 + 1.0 * seq * STEP / 1e9, 50.0], std_m=[3.0, 3.0])))


def test_a_sensor_clock_jumping_ahead_and_back_costs_only_those_messages() -> None:
    cfg = load_service_config(SERVICE_TOML)
    pipe = Pipeline(Tracker(cfg.tracker), wire.Codec(cfg.namespace),
                    max_future_wall_ns=round(cfg.intake.max_future_wall_s * 1e9))
    key = m.meas_key(cfg.namespace, "cam1")
    ahead, behind = range(30, 35), range(60, 65)
    ids_before: set[int] = set()
    for seq in range(100):
        arrival = T0 + seq * STEP + 5_000_000  # arrives 5 ms after it was measured
        t = arrival - 5_000_000
        if seq in ahead:
            t += 2 * 3600 * 10**9  # two hours ahead: past max_future_wall_s (1 h)
        elif seq in behind:
            t -= 60 * 10**9  # a minute behind: far outside the 2 s window
        pipe.ingest([(arrival, key, _cam(seq, t))])
        if seq == 29:
            ids_before = {tr.id for tr in pipe.tracker.confirmed()}
    c = pipe.counts()
    assert c.refused.get("future", 0) == len(ahead), c.refused
    assert c.refused.get("too_late", 0) == len(behind), c.refused
    assert c.applied == 100 - len(ahead) - len(behind)
    assert c.received == c.applied + c.inputs + c.truth + sum(c.refused.values())
    assert len(ids_before) == 1, "one target, one confirmed track before the jumps"
    assert {tr.id for tr in pipe.tracker.confirmed()} == ids_before, "the jumps broke the track"
    assert pipe.tracker.now_ns is not None and pipe.tracker.now_ns < T0 + 100 * STEP, "the leap moved the clock"
