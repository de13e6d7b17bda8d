"""Property tests (hypothesis, bounded in time): the decoder, and the tracker behind it, fed
hostile and valid-but-nasty messages. The decoder returns a valid message or raises a
MessageError, nothing else; the pipeline never raises, its counts add up, and whatever it
publishes is finite with a symmetric covariance. tools/fuzz.py runs the same for longer."""

from __future__ import annotations

import contextlib
import math

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusion import messages as m
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from tests.security import nasty
from tests.service.harness import scenario_config

PROFILE = settings(max_examples=300, deadline=None, derandomize=True,
                   suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
ID_RE = r"[A-Za-z0-9_.\-]{1,64}"


def _check_decoded(data: bytes) -> None:
    try:
        msg = m.decode_measurement(data)
    except m.MessageError:
        return
    import re

    assert re.fullmatch(ID_RE, msg.sensor_id)
    assert -(2**62) <= msg.t_ns <= 2**62 and 0 <= msg.seq <= 2**62
    values = msgspec.to_builtins(msg.data)
    for v in values.values():
        for x in (v if isinstance(v, list) else [v]):
            assert not isinstance(x, float) or math.isfinite(x)


@PROFILE
@given(st.one_of(st.binary(max_size=300), nasty.mutated()))
def test_the_decoder_on_arbitrary_and_mutated_bytes(data: bytes) -> None:
    _check_decoded(data)


@PROFILE
@given(nasty.measurement_like())
def test_the_decoder_on_measurement_like_structures(data: bytes) -> None:
    _check_decoded(data)


@PROFILE
@given(nasty.msgpack_values)
def test_every_decoder_on_arbitrary_msgpack(value) -> None:
    data = msgspec.msgpack.encode(value)
    for dec in (m.decode_measurement, m.decode_truth, m.decode_input, m.decode_any):
        with contextlib.suppress(m.MessageError):
            dec(data)


_CFG = scenario_config("mix")[1]


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.lists(st.lists(nasty.nasty_measurement(), min_size=1, max_size=8), min_size=1, max_size=4),
       st.integers(0, 2**62))
def test_the_tracker_fed_valid_but_nasty_measurements(batches, arrival0: int) -> None:
    tracker = Tracker(_CFG.tracker)
    pipe = Pipeline(tracker, wire.Codec("demo"), max_future_wall_ns=3600 * 10**9)
    n = 0
    for k, batch in enumerate(batches):
        recs = [(arrival0 + k * 10**8 + i, m.meas_key("demo", x.sensor_id), m.encode(x)) for i, x in enumerate(batch)]
        n += len(recs)
        out = pipe.ingest(recs)
        for e in out.result.estimates:
            assert np.all(np.isfinite(e.x)) and np.all(np.isfinite(e.P)), e
            assert np.allclose(e.P, e.P.T, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(e.P), initial=1.0)))
    c = pipe.counts()
    assert c.received == n == c.applied + c.inputs + c.truth + sum(c.refused.values())


@pytest.mark.parametrize("data", [
    m.Cartesian(pos_m=[5e-324, 0.0]), m.Cartesian(pos_m=[3.2e11, 2.0]),
    m.Radar(range_m=1.0, bearing_rad=1.0, range_std_m=1.0, bearing_std_rad=1e-12),
    m.Radar(range_m=1.0, bearing_rad=1.0, range_std_m=187.0, bearing_std_rad=1e-6)],
    ids=["cartesian-5e-324", "cartesian-3e11", "std-1e-12", "std-187-1e-6"])
def test_extreme_valid_radar_data_is_refused_not_raised(data: m.Cartesian | m.Radar) -> None:
    """Found by the property test above: Cartesian data on a radar's key were read as (range,
    bearing), and a radar's own noise could make a new track's P singular; both escaped
    Pipeline.ingest as NotPositiveDefiniteError. Now refused with a reason."""
    pipe = Pipeline(Tracker(_CFG.tracker), wire.Codec("demo"))
    msg = m.Measurement(sensor_id="radar1", t_ns=0, seq=0, data=data)
    pipe.ingest([(0, m.meas_key("demo", "radar1"), m.encode(msg))])
    assert sum(pipe.counts().refused.values()) == 1


def test_a_radar_range_outside_the_bounds_is_refused_at_decode() -> None:
    """Found by the property test above: these ranges made the new track's P singular."""
    for r in (5e-324, 1e-3, 3.19e11):
        msg = m.Measurement(sensor_id="radar1", t_ns=0, seq=0, data=m.Radar(range_m=r, bearing_rad=2.0))
        with pytest.raises(m.InvalidMessageError, match="range_m"):
            m.decode_measurement(m.encode(msg))
