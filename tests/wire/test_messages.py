"""The wire schema: round trips for every kind, and bad input refused with the field named."""

from __future__ import annotations

import math

import pytest

from fusion import messages as m

MEAS = [
    m.Measurement(sensor_id="cam1", t_ns=10, seq=0, data=m.Cartesian(pos_m=[1.0, 2.0], std_m=[0.5, 0.5])),
    m.Measurement(sensor_id="cam1", t_ns=10, seq=1, data=m.Cartesian(pos_m=[1.0, 2.0, 3.0],
                                                                      cov_m2=[1, 0, 0, 0, 1, 0, 0, 0, 1])),
    m.Measurement(sensor_id="r1", t_ns=-5, seq=7, data=m.Radar(range_m=10.0, bearing_rad=-math.pi, range_std_m=1.0,
                                                              bearing_std_rad=0.01)),
    m.Measurement(sensor_id="r1", t_ns=2**61, seq=8, data=m.Radar(
        range_m=10.0, bearing_rad=1.0, range_std_m=1.0, bearing_std_rad=0.01, elevation_rad=0.2,
        elevation_std_rad=0.01, range_rate_mps=-3.0, range_rate_std_mps=0.5)),
]
OTHERS = [
    m.Truth(target_id="t0", t_ns=1, state=[1.0, 2.0], layout=["x", "vx"]),
    m.Estimate(track_id=2**62, t_ns=1, sensor_id="r1", seq=3, state=[1.0, 2.0], cov=[1.0, 0.0, 0.0, 1.0],
               layout=["x", "vx"], model="cv", status="confirmed", revision=2, nis=1.5, mode_probabilities=[0.3, 0.7]),
    m.ServiceStatus(uptime_s=1.0, counts=m.Counts(received=3, applied=1, duplicates=1, refused={"invalid": 1},
                                                   queued=0, replays=0, late_applied=0, published=1, truth=0),
                    tracks={"confirmed": 1}, latency={"r1": m.LatencyStats(count=1, mean_ms=1, p50_ms=1, p99_ms=1,
                                                                            max_ms=1)},
                    recording=None, recording_bytes=0, queue_depth=0),
]


@pytest.mark.parametrize("msg", MEAS + OTHERS, ids=lambda x: type(x).__name__)
def test_round_trip_msgpack_and_json(msg: m.Message) -> None:
    assert m.decode_any(m.encode(msg)) == msg
    assert m.decode_json(m.encode_json(msg)) == msg


def test_snapshot_round_trip() -> None:
    snap = m.Snapshot(estimates=[OTHERS[1]])
    assert m.decode_snapshot(m.encode(snap)) == snap


def _json(data: str, *, sensor: str = '"r1"', extra: str = "") -> bytes:
    return f'{{"type":"measurement","sensor_id":{sensor},"t_ns":5,"seq":0{extra},"data":{data}}}'.encode()


RADAR = '{{"type":"radar","range_m":{r},"bearing_rad":{b},"range_std_m":{s},"bearing_std_rad":0.01}}'
BAD = {
    "huge": (_json('{"type":"cartesian","pos_m":[1,1e300],"std_m":[1,1]}'), "pos_m"),
    "angle": (_json(RADAR.format(r=10, b=4.0, s=1)), "bearing_rad"),
    "negative-std": (_json(RADAR.format(r=10, b=0.1, s=-1)), "range_std_m"),
    "zero-range": (_json(RADAR.format(r=0, b=0.1, s=1)), "range_m"),
    "dimension": (_json('{"type":"cartesian","pos_m":[1,2],"std_m":[1]}'), "std_m must have 2"),
    "cov-dimension": (_json('{"type":"cartesian","pos_m":[1,2],"cov_m2":[1,0,1]}'), "cov_m2 must have 4"),
    "both-noises": (_json('{"type":"cartesian","pos_m":[1,2],"std_m":[1,1],"cov_m2":[1,0,0,1]}'), "at most one"),
    "unknown-field": (_json(RADAR.format(r=10, b=0.1, s=1), extra=',"colour":1'), "unknown field `colour`"),
    "missing-field": (b'{"type":"measurement","sensor_id":"r1","t_ns":5,"data":{"type":"cartesian","pos_m":[1],'
                      b'"std_m":[1]}}', "missing required field `seq`"),
    "wrong-type": (_json(RADAR.format(r='"far"', b=0.1, s=1)), "range_m"),
    "bad-id": (_json(RADAR.format(r=10, b=0.1, s=1), sensor='"a/b"'), "sensor_id"),
    "half-range-rate": (_json('{"type":"radar","range_m":1,"bearing_rad":0,"range_std_m":1,"bearing_std_rad":0.1,'
                              '"range_rate_mps":1}'), "a standard deviation for every value present"),
    "std-without-value": (_json('{"type":"radar","range_m":1,"bearing_rad":0,"range_std_m":1,"bearing_std_rad":0.1,'
                                '"elevation_std_rad":0.1}'), "given for a value that is absent"),
}


@pytest.mark.parametrize(("data", "field"), BAD.values(), ids=BAD.keys())
def test_bad_input_names_the_field(data: bytes, field: str) -> None:
    with pytest.raises(m.MessageError, match="invalid") as e:
        m.decode_json(data)
    assert field in str(e.value)
    import msgspec

    with pytest.raises(m.MessageError, match="invalid"):  # the same refusal in msgpack
        m.decode_measurement(msgspec.msgpack.encode(msgspec.json.decode(data)))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_non_finite_in_msgpack_is_refused(bad: float) -> None:
    raw = m.encode(m.Measurement(sensor_id="a", t_ns=1, seq=0, data=m.Cartesian(pos_m=[1.0, bad], std_m=[1, 1])))
    with pytest.raises(m.MessageError, match=r"\$\.data\.pos_m\[1\]"):
        m.decode_measurement(raw)


def test_nan_is_not_json() -> None:
    with pytest.raises(m.MessageError, match="malformed"):
        m.decode_json(_json(RADAR.format(r="NaN", b=0.1, s=1)))


def test_truncated_bytes_are_malformed() -> None:
    raw = m.encode(MEAS[0])
    with pytest.raises(m.MessageError, match="malformed"):
        m.decode_measurement(raw[:-2])


def test_keys() -> None:
    assert m.meas_key("ns", "r1") == "fusion/ns/meas/r1"
    assert m.all_meas_key("ns") == "fusion/ns/meas/*"
    assert m.track_key("ns", 12) == "fusion/ns/tracks/12"
    assert m.key_kind("fusion/ns/truth/t0") == "truth"
    for bad in ("a/b", "a*", "", "x y", "$x"):
        with pytest.raises(m.InputError):
            m.meas_key("ns", bad)


def test_every_message_carries_its_schema_version() -> None:
    import msgspec

    for msg in MEAS + OTHERS:
        assert msgspec.msgpack.decode(m.encode(msg))["v"] == m.SCHEMA_VERSION
        assert msgspec.json.decode(m.encode_json(msg))["v"] == m.SCHEMA_VERSION


def test_an_unknown_schema_version_is_refused_with_the_reason() -> None:
    import msgspec

    from fusion.errors import UnsupportedVersionError

    raw = msgspec.msgpack.decode(m.encode(MEAS[0]))
    raw["v"] = m.SCHEMA_VERSION + 1
    with pytest.raises(UnsupportedVersionError, match=f"this service reads version {m.SCHEMA_VERSION}"):
        m.decode_measurement(msgspec.msgpack.encode(raw))
    del raw["v"]  # a sender that leaves it out speaks version 1
    assert m.decode_measurement(msgspec.msgpack.encode(raw)) == MEAS[0]


def test_a_measurement_without_noise_takes_the_sensors_configured_noise() -> None:
    from fusion.io.wire import detection_of

    d = detection_of(m.Measurement(sensor_id="r1", t_ns=1, seq=0, data=m.Radar(range_m=10.0, bearing_rad=0.1)))
    assert d.R is None
    d = detection_of(m.Measurement(sensor_id="c", t_ns=1, seq=0, data=m.Cartesian(pos_m=[1.0, 2.0])))
    assert d.R is None


def test_malformed_and_invalid_are_distinct_classes() -> None:
    import msgspec

    from fusion.errors import InvalidMessageError, MalformedMessageError, UnsupportedVersionError

    assert not issubclass(MalformedMessageError, InvalidMessageError)
    assert not issubclass(InvalidMessageError, MalformedMessageError)
    assert issubclass(UnsupportedVersionError, InvalidMessageError)
    raw = m.encode(MEAS[0])
    with pytest.raises(MalformedMessageError) as e:
        m.decode_measurement(raw[:-2])
    assert not isinstance(e.value, InvalidMessageError)
    bad = msgspec.msgpack.decode(raw)
    bad["seq"] = "zero"
    with pytest.raises(InvalidMessageError) as e2:
        m.decode_measurement(msgspec.msgpack.encode(bad))
    assert not isinstance(e2.value, (MalformedMessageError, UnsupportedVersionError))


@pytest.mark.parametrize("v", [0, m.SCHEMA_VERSION + 1, 2**40], ids=["zero", "next", "huge"])
def test_the_version_is_read_as_a_value(v: int) -> None:
    """An unsupported version is told by the message's `v`, also when other fields are wrong
    too; a `v` that is not an integer is an invalid field."""
    import msgspec

    from fusion.errors import UnsupportedVersionError

    raw = msgspec.msgpack.decode(m.encode(MEAS[0]))
    raw.update(v=v, seq="zero")
    with pytest.raises(UnsupportedVersionError):
        m.decode_measurement(msgspec.msgpack.encode(raw))
    with pytest.raises(UnsupportedVersionError):
        m.decode_json(msgspec.json.encode(raw))
    raw["v"] = "one"
    with pytest.raises(m.InvalidMessageError) as e:
        m.decode_measurement(msgspec.msgpack.encode(raw))
    assert not isinstance(e.value, UnsupportedVersionError)


def test_malformed_and_invalid_are_counted_apart() -> None:
    import msgspec

    from fusion.config import CartesianSensorConfig, TrackerConfig
    from fusion.io import wire
    from fusion.pipeline import Pipeline
    from fusion.tracking.tracker import Tracker

    cfg = TrackerConfig(sensors=[CartesianSensorConfig(id="cam1", std_m=[1.0, 1.0])])
    pipe = Pipeline(Tracker(cfg), wire.Codec("ns"))
    key = m.meas_key("ns", "cam1")
    good = m.encode(m.Measurement(sensor_id="cam1", t_ns=10, seq=0, data=m.Cartesian(pos_m=[1.0, 2.0])))
    invalid = msgspec.msgpack.encode({**msgspec.msgpack.decode(good), "seq": -1})
    newer = msgspec.msgpack.encode({**msgspec.msgpack.decode(good), "v": m.SCHEMA_VERSION + 1})
    records = [(1, key, good), (2, key, good[:-3]), (3, key, b"\xc1"), (4, key, invalid), (5, key, invalid),
               (6, key, invalid), (7, key, newer)]
    pipe.ingest(records)
    c = pipe.counts()
    assert c.applied == 1
    assert {r.value: n for r, n in c.refused.items()} == {"malformed": 2, "invalid": 3, "unsupported_version": 1}


def _radar_rule(elev: bool, rate: bool, stds: tuple[bool, bool, bool, bool]) -> str | None:
    """The Radar noise rule, stated independently of messages.Radar.__post_init__'s fast path."""
    if (stds[2] and not elev) or (stds[3] and not rate):
        return "given for a value that is absent"
    present = [stds[0], stds[1]] + ([stds[2]] if elev else []) + ([stds[3]] if rate else [])
    return None if all(present) or not any(present) else "a standard deviation for every value present"


@pytest.mark.parametrize("mask", range(64), ids=lambda k: f"{k:06b}")
def test_every_radar_noise_combination_is_judged_by_the_rule(mask: int) -> None:
    """All 64 combinations of elevation, range rate and the four standard deviations present:
    decode accepts exactly those the rule accepts, and refuses the others with its reason."""
    elev, rate, *stds = (bool(mask >> k & 1) for k in range(6))
    fields = {"range_m": 10.0, "bearing_rad": 0.1}
    for name, on, value in [("elevation_rad", elev, 0.2), ("range_rate_mps", rate, -1.0),
                            ("range_std_m", stds[0], 1.0), ("bearing_std_rad", stds[1], 0.01),
                            ("elevation_std_rad", stds[2], 0.01), ("range_rate_std_mps", stds[3], 0.5)]:
        if on:
            fields[name] = value
    import msgspec

    raw = msgspec.msgpack.encode({"type": "measurement", "sensor_id": "r1", "t_ns": 5, "seq": 0,
                                  "data": {"type": "radar", **fields}})
    want = _radar_rule(elev, rate, tuple(stds))  # type: ignore[arg-type]
    if want is None:
        assert m.decode_measurement(raw).data.has_noise == stds[0]
    else:
        with pytest.raises(m.InvalidMessageError, match=want):
            m.decode_measurement(raw)


@pytest.mark.parametrize("d", [0, 1, 2, 3, 4], ids=lambda d: f"d{d}")
@pytest.mark.parametrize("noise", ["none", "std-", "std", "std+", "cov-", "cov", "both"], ids=str)
def test_every_cartesian_shape_is_judged_by_the_rule(d: int, noise: str) -> None:
    fields: dict[str, object] = {"pos_m": [1.0] * d}
    if noise.startswith("std") or noise == "both":
        fields["std_m"] = [1.0] * (d + {"std-": -1, "std+": 1}.get(noise, 0) if d else 1)
    if noise.startswith("cov") or noise == "both":
        fields["cov_m2"] = [1.0] * (d * d - (noise == "cov-"))
    import msgspec

    raw = msgspec.msgpack.encode({"type": "measurement", "sensor_id": "c", "t_ns": 5, "seq": 0,
                                  "data": {"type": "cartesian", **fields}})
    std, cov = fields.get("std_m"), fields.get("cov_m2")
    ok = (d in (1, 2, 3) and not (std is not None and cov is not None)
          and (std is None or len(std) == d) and (cov is None or len(cov) == d * d))  # type: ignore[arg-type]
    if ok:
        assert m.decode_measurement(raw).data.pos_m == [1.0] * d
    else:
        with pytest.raises(m.InvalidMessageError):
            m.decode_measurement(raw)


@pytest.mark.parametrize("n", [0, 1, 15, 16, 17, 65535, 65536], ids=lambda n: f"n{n}")
def test_a_snapshot_of_encoded_estimates_is_the_snapshot_encoded(n: int) -> None:
    """The service joins the bytes it published into the snapshot answer: the same bytes as
    encoding the Snapshot, across the msgpack array header's three sizes."""
    from fusion.io import wire

    ests = [m.Estimate(track_id=i, t_ns=i, sensor_id="r1", seq=i, state=[float(i)], cov=[1.0], layout=["x"],
                       model="cv", status="confirmed", revision=0) for i in range(n)]
    got = wire.snapshot_of_encoded([m.encode(e) for e in ests])
    assert got == wire.encode_snapshot(ests)
    assert m.decode_snapshot(got).estimates == ests


@pytest.mark.parametrize("case", ["imm", "cv-no-nis", "retracted-empty", "negative-seq"], ids=str)
def test_the_estimate_encoder_writes_the_estimate_message(case: str) -> None:
    """The service's encoder (positional, fusion.io.wire) and the schema's Estimate give the
    same bytes, optional fields left off the same way."""
    import numpy as np

    from fusion.io import wire
    from fusion.tracking.results import Estimate

    layout = ("x", "vx", "y", "vy")
    x, P = np.arange(4.0), np.arange(16.0).reshape(4, 4)
    e = {
        "imm": Estimate(7, 10**18, "radar1", 3, x, P, "confirmed", 2, 1.25, np.array([0.25, 0.75])),
        "cv-no-nis": Estimate(7, -5, "cam1", 0, x, P, "tentative", 0, None),
        "retracted-empty": Estimate(2**62, 5, "cam1", 9, np.zeros(0), np.zeros((0, 0)), "retracted", 4, None),
        "negative-seq": Estimate(1, 5, "cam1", -1, x, P, "predicted", 0, None),
    }[case]
    want = m.encode(wire.estimate_message(e, layout=layout, model="imm_cv"))
    assert wire.estimate_encoder(layout, "imm_cv")(e) == want
    assert m.decode_estimate(want).layout == (list(layout) if e.x.size else [])
