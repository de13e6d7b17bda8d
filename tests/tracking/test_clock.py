"""The window follows a clock one message cannot push, recovers after silence, and acceptance
does not depend on how arrivals are batched (issue #9, defect 8)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from fusion.config import TimeConfig
from fusion.tracking.detection import Detection, Reason
from tests.tracking.helpers import make_tracker
from tests.tracking.streams import NS_PER_S, Sensor, constant_velocity, detect, in_order

S = NS_PER_S
CART = Sensor("cart", "cartesian", period_s=0.1, std_m=1.0)


def outcomes(tr, dets: list[Detection]) -> list[Reason | None]:
    out = []
    for d in dets:
        r = tr.process([d])
        out.append(r.refused[0].reason if r.refused else None)
    return out


def test_one_message_from_the_future_does_not_lock_out_real_data() -> None:
    """Real data every 0.1 s; one message stamped 9 s ahead (inside future_s) is accepted, but
    the next 7 s of real data are not refused as too late."""
    tr = make_tracker([CART], time=TimeConfig(lag_s=2.0, future_s=10.0))
    real = [Detection.of("cart", k * S // 10, k, [float(k), 0.0]) for k in range(100)]
    rogue = Detection.of("cart", 5 * S + 9 * S, 10_000, [500.0, 500.0])
    got = outcomes(tr, real[:50] + [rogue] + real[50:])
    assert got == [None] * 101


@pytest.mark.parametrize("arrival", [True, False], ids=["with-arrival-times", "sensor-times-only"])
def test_the_clock_recovers_after_a_silence_longer_than_future_s(arrival: bool) -> None:
    tr = make_tracker([CART], time=TimeConfig(lag_s=2.0, future_s=10.0))

    def d(t_s: float, seq: int) -> Detection:
        t = round(t_s * S)
        return Detection.of("cart", t, seq, [0.0, 0.0], arrival_ns=t + 50_000_000 if arrival else None)

    assert outcomes(tr, [d(0.0, 0)]) == [None]
    later = [d(100.0 + 0.1 * k, 1 + k) for k in range(5)]
    got = outcomes(tr, later)
    if arrival:  # the arrival clock moved on with the silence: nothing is lost
        assert got == [None] * 5
    else:  # only the data says time jumped: clock_outliers + 1 = 2 detections must agree
        assert got == [Reason.FUTURE, None, None, None, None]


BATCH_SIZES = [1, 2, 3, 7, 50, 1000, 5000]


@pytest.mark.parametrize("size", BATCH_SIZES, ids=[f"batch{n}" for n in BATCH_SIZES])
def test_acceptance_does_not_depend_on_batching(size: int) -> None:
    """A stream with late, duplicate, too-late and future data: the refusals (and the tracks)
    are the same whether it is processed one detection at a time or in batches."""
    rng = np.random.default_rng(5)
    truth = constant_velocity(n_targets=3, duration_s=30.0, rng=rng)
    good = [x.det for x in in_order(detect(truth, CART, rng=rng, clutter_mean=0.5, region_m=(-300, 300, -300, 300)))]
    stream: list[Detection] = []
    for k, d in enumerate(good):
        stream.append(d)
        if k % 17 == 0:
            stream.append(d)  # a duplicate
        if k % 101 == 0 and k:
            stream.append(Detection.of("cart", d.t_ns - 5 * S, 90_000 + k, [0.0, 0.0]))  # too late
        if k % 211 == 0:
            stream.append(Detection.of("cart", d.t_ns + 60 * S, 80_000 + k, [0.0, 0.0]))  # future
    # the seq counter restarts at 0 half-way: new measurements, not duplicates
    stream += [Detection(d.sensor_id, d.t_ns + 31 * S, d.seq, d.z, d.R) for d in good[:50]]

    def run(n: int):
        tr = make_tracker([CART], time=TimeConfig(lag_s=2.0))
        refused = []
        it = iter(stream)
        while batch := list(itertools.islice(it, n)):
            refused += [(r.sensor_id, r.seq, r.t_ns, r.reason) for r in tr.process(batch).refused]
        return refused, sorted((t.id, t.state.x.tobytes()) for t in tr.tracks), tr.counts

    ref_refused, ref_tracks, ref_counts = run(1)
    refused, tracks, counts = run(size)
    assert refused == ref_refused
    assert tracks == ref_tracks
    assert counts.refused == ref_counts.refused and counts.applied == ref_counts.applied
    assert ref_counts.refused[Reason.DUPLICATE] == len(range(0, len(good), 17))
    assert Reason.FUTURE in ref_counts.refused and Reason.TOO_LATE in ref_counts.refused


RADAR = Sensor("radar", "radar", period_s=0.1, range_std_m=2.0, bearing_std_rad=0.003, position_m=(-500.0, 0.0))


def _two_sensor_stream(seconds: float = 20.0) -> list[Detection]:
    rng = np.random.default_rng(8)
    truth = constant_velocity(n_targets=2, duration_s=seconds, rng=rng, spread_m=200.0)
    return [x.det for x in in_order(detect(truth, CART, rng=rng), detect(truth, RADAR, rng=rng))]


def test_one_sources_whole_backlog_before_anothers_loses_nothing() -> None:
    """Zenoh keeps order per key, not across keys: at full speed a whole sensor's stream can
    arrive before another's. The window follows the slowest source, so nothing is too late."""
    dets = _two_sensor_stream()
    a0 = 10**18
    order = [d for d in dets if d.sensor_id == "cart"] + [d for d in dets if d.sensor_id == "radar"]
    tr = make_tracker([CART, RADAR], time=TimeConfig(lag_s=2.0))
    r = tr.process([Detection(d.sensor_id, d.t_ns, d.seq, d.z, d.R, a0 + k * 1000) for k, d in enumerate(order)])
    assert not r.refused and r.applied == len(dets)


def test_a_slow_sensor_is_not_late_because_another_is_fast() -> None:
    """The radar's data arrive 1.5 s after the camera's (lag 1 s): still in the window."""
    dets = _two_sensor_stream()
    arrival = {id(d): d.t_ns + (1_500_000_000 if d.sensor_id == "radar" else 20_000_000) for d in dets}
    order = sorted(dets, key=lambda d: arrival[id(d)])
    tr = make_tracker([CART, RADAR], time=TimeConfig(lag_s=1.0))
    refused = []
    for d in order:
        refused += tr.process([Detection(d.sensor_id, d.t_ns, d.seq, d.z, d.R, arrival[id(d)])]).refused
    assert refused == []


def test_a_silent_sensor_stops_holding_the_window_back() -> None:
    """A configured radar that never speaks holds the window for source_idle_s, then no more:
    the history stays bounded."""
    tr = make_tracker([CART, RADAR], time=TimeConfig(lag_s=1.0, source_idle_s=3.0))
    cart = [d for d in _two_sensor_stream(30.0) if d.sensor_id == "cart"]
    for d in cart:
        tr.process([Detection(d.sensor_id, d.t_ns, d.seq, d.z, d.R, d.t_ns + 10_000_000)])
    assert tr.horizon_ns is not None and tr.horizon_ns > 25 * S
    assert len(tr.history) <= 11  # the scans of the last lag_s (0.1 s apart)
