"""Intake.admit_many (the tracker's admission of a batch: the clocks and the window in one
compiled pass, fusion.tracking.window_kernel) is admit of each detection in turn: the same
detections accepted, the same refusals in the same order with the same words, and the same
state after (every source's clock, the first arrival, the newest reference, the horizon, the
duplicates), in every state the intake goes through, however the stream is cut into batches."""

from __future__ import annotations

import numpy as np
import pytest

from fusion.config import load_service_config
from fusion.tracking.detection import Detection
from fusion.tracking.intake import Intake
from fusion.tracking.tracker import Tracker
from fusion.tracking.window_kernel import LIMIT_T

CONFIG = load_service_config("configs/service.toml").tracker


def _intake(samples: int, outliers: int) -> Intake:
    tr = Tracker(CONFIG)
    t = CONFIG.time
    return Intake(tr.sensors, type(t)(**{**{f: getattr(t, f) for f in t.__struct_fields__},
                                         "clock_samples": samples, "clock_outliers": outliers}))


def _state(i: Intake) -> tuple[object, ...]:
    c = i.clocks
    return (c.first_arrival_ns, tuple((s, k.state(), k.offset, k.settled) for s, k in c.sources.items()),
            i.now_ns, i.horizon_ns, i.committed, i.seen_len)


def _key(d: Detection) -> tuple[object, ...]:
    return d.sensor_id, d.t_ns, d.seq, d.epoch, d.arrival_ns, d.z.tolist(), None if d.R is None else d.R.tolist()


G = 50_000_000  # times on a 50 ms grid, so that the rules' ties (t = ref + future_s, a - last = idle_s,
# (t, sensor) = the committed scan) happen


def _stream(rng: np.random.Generator, n: int, *, no_arrival: float) -> list[Detection]:
    """Detections of radar1, cam1 and an unknown sensor, arrival times drifting forward with
    jitter and silences, sensor times near them, some far ahead or behind, some invalid, some
    repeated."""
    out: list[Detection] = []
    arrival = 10**18 + G * int(rng.integers(0, 10**6))
    seq = {"radar1": 0, "cam1": 0, "ghost": 0}
    idle = int(CONFIG.time.source_idle_s * 1e9)
    first = arrival
    late_start = bool(rng.integers(0, 2))  # cam1 silent at first, the watermark waiting for it
    for _ in range(n):
        arrival += G * int(rng.integers(0, 4))
        if rng.random() < 0.02:
            arrival += idle  # a silence, as long as a source may be idle
        if out and rng.random() < 0.05:  # a duplicate (the same identity, arriving again)
            d = out[int(rng.integers(0, len(out)))]
            out.append(d._replace(arrival_ns=None if d.arrival_ns is None else arrival))
            continue
        s = str(rng.choice(["radar1", "cam1", "ghost"], p=[0.55, 0.4, 0.05]))
        if s == "cam1" and late_start and arrival - first < idle + G:
            s = "radar1"
        seq[s] += 1
        t = arrival + G * int(rng.integers(-6, 3))
        u = rng.random()
        if u < 0.03:
            t += int(CONFIG.time.future_s * 1e9) + G * int(rng.integers(-2, 3))  # about as far ahead as allowed
        elif u < 0.07:
            t -= G * int(rng.integers(20, 120))  # behind: too late for some
        radar = s == "radar1"
        z = np.array([float(rng.uniform(100.0, 9000.0)), float(rng.uniform(-3.0, 3.0))] if radar else
                     rng.normal(0.0, 500.0, 2).tolist())
        if rng.random() < 0.02:
            z[1] = np.nan  # invalid
        a = None if rng.random() < no_arrival else arrival
        out.append(Detection(s, t, seq[s], z, None, a, int(rng.integers(0, 2)), radar if s != "ghost" else None))
    return out


def _not_one_at_a_time(*_args: object) -> None:
    raise AssertionError("a batch of detections all with or all without arrival times went one at a time")


@pytest.mark.parametrize("seed", range(12))
def test_admit_many_is_admit_one_at_a_time(seed: int) -> None:
    rng = np.random.default_rng(seed)
    samples, outliers = int(rng.integers(1, 17)), 0
    outliers = int(rng.integers(0, samples))
    one, many = _intake(samples, outliers), _intake(samples, outliers)
    if seed % 4 in (0, 3):  # every batch all with or all without arrival times: the compiled pass takes them all
        many._window = _not_one_at_a_time  # type: ignore[method-assign]
    dets = _stream(rng, 3000, no_arrival=0.002 if seed % 2 else 0.0)
    if seed % 4 == 2:  # without arrival times from the middle on (the clocks hold timed offsets then)
        dets = dets[:1500] + [d._replace(arrival_ns=None) for d in dets[1500:]]
    elif seed % 4 == 3:  # none at all: a caller of Tracker without them
        dets = [d._replace(arrival_ns=None) for d in dets]
    k = 0
    while k < len(dets):
        batch = dets[k:k + int(rng.integers(1, 300))]
        k += len(batch)
        want_ok, want_bad = [], []
        for d in batch:
            ok, bad = one.admit(d)
            if ok is not None:
                want_ok.append(ok)
            else:
                want_bad.append(bad)
        got_ok, got_bad = many.admit_many(batch)
        assert [_key(d) for d in got_ok] == [_key(d) for d in want_ok], k
        assert got_bad == want_bad, k
        assert _state(many) == _state(one), k
        if rng.random() < 0.3 and want_ok:  # the history commits a scan early, ahead of the horizon
            d = want_ok[int(rng.integers(0, len(want_ok)))]
            key = (d.t_ns - G * int(rng.integers(0, 3)), str(rng.choice(["cam1", "radar1"])))
            one.commit(key)
            many.commit(key)
    assert one.now_ns is not None and one.horizon_ns is not None


def test_a_time_beyond_the_kernels_range_is_admitted_one_at_a_time() -> None:
    """Times whose sums could overflow int64 go through the Python path, with its big ints."""
    one, many = _intake(4, 1), _intake(4, 1)
    z = np.array([10.0, 20.0])
    batch = [Detection("cam1", t, i, z, None, t + 1000, 0, False)
             for i, t in enumerate([10**18, 10**18 + 5, LIMIT_T + 1, 10**18 + 9])]
    want = [one.admit(d) for d in batch]
    got_ok, got_bad = many.admit_many(batch)
    assert [_key(d) for d in got_ok] == [_key(d) for d, bad in want if bad is None]
    assert got_bad == [bad for _, bad in want if bad is not None]
    assert _state(many) == _state(one)


def test_ties_at_the_idle_bound_are_the_pythons() -> None:
    """At exactly source_idle_s after the first arrival a source never heard is no longer waited
    for, and at exactly source_idle_s after its last arrival a source still holds the watermark
    back: the horizon after each detection is the one admit gives."""
    idle, lag = int(CONFIG.time.source_idle_s * 1e9), int(CONFIG.time.lag_s * 1e9)
    t0, z = 10**18, np.array([10.0, 20.0])
    steps = [("cam1", t0, t0), ("cam1", t0 + idle - G, t0 + idle - G), ("cam1", t0 + idle, t0 + idle),
             ("radar1", t0 + idle + G - 10 * G, t0 + idle + G), ("cam1", t0 + 2 * idle + G, t0 + 2 * idle + G)]
    one, many = _intake(16, 1), _intake(16, 1)
    horizons = []
    for k, (s, t, a) in enumerate(steps):
        d = Detection(s, t, k, np.array([500.0, 0.1]) if s == "radar1" else z, None, a, 0, s == "radar1")
        assert one.admit(d)[1] is None
        ok, bad = many.admit_many([d])
        assert len(ok) == 1 and not bad
        assert _state(many) == _state(one), k
        horizons.append(many.horizon_ns)
    # waited for radar1 until idle_s after the first arrival, then cam1's clock alone; radar1's
    # lower clock holds it back while it was heard within idle_s, the bound included
    assert horizons == [None, None, t0 + idle - lag, t0 + idle - lag, t0 + 2 * idle + G - 10 * G - lag]


def test_detections_without_arrival_times_after_timed_ones() -> None:
    """A batch without arrival times after timed ones (a caller mixing the two): the compiled
    pass forgets the last arrival of each source it observes, as the clocks do, and judges by
    the offsets the timed detections left."""
    one, many = _intake(8, 1), _intake(8, 1)
    many._window = _not_one_at_a_time  # type: ignore[method-assign]
    t0, z = 10**18, np.array([10.0, 20.0])
    timed = [Detection(s, t0 + k * G, k, np.array([500.0, 0.1]) if s == "radar1" else z, None, t0 + k * G + G, 0,
                       s == "radar1") for k, s in enumerate(["radar1", "cam1"] * 6)]
    untimed = [Detection("radar1", t0 + (12 + k) * G, 12 + k, np.array([500.0, 0.1]), None, None, 0, True)
               for k in range(4)] + [Detection("radar1", t0 - 100 * G, 99, np.array([500.0, 0.1]), None, None, 0, True)]
    for batch in (timed, untimed):
        want = [one.admit(d) for d in batch]
        got_ok, got_bad = many.admit_many(batch)
        assert [_key(d) for d in got_ok] == [_key(d) for d, bad in want if bad is None]
        assert got_bad == [bad for _, bad in want if bad is not None]
        assert _state(many) == _state(one)
    assert one.clocks.sources["radar1"].last_arrival_ns is None
    assert one.clocks.sources["cam1"].last_arrival_ns is not None
    # the first is judged by radar1's clock as the timed ones left it: offset -50 ms (they
    # arrived 50 ms after their time), so without an arrival time the reference is -50 ms and
    # its sensor time, 10^18 ns, is far ahead of it (future); the rest by the clock once their
    # own offsets lead it; the last one too late
    assert [(b.reason.value, b.seq) for b in got_bad] == [("future", 12), ("too_late", 99)]
