"""A batch's measurements decoded in one loop (messages.decode_measurements,
wire.Codec.detections) give exactly what decoding each alone gives, refusals included."""

from __future__ import annotations

import itertools
import math

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.detection import Detection
from fusion.tracking.tracker import Tracker
from tests.service.harness import scenario_config
from tests.service.test_service import GOOD_SENSOR, _good_and_bad

NS = "demo"


def _radar(seq: int, **kw: object) -> bytes:
    data = dict(range_m=1000.0 + seq, bearing_rad=0.1, range_std_m=5.0, bearing_std_rad=0.003)
    data.update(kw)
    return m.encode(m.Measurement(sensor_id="radar1", t_ns=10**9 + seq, seq=seq, data=m.Radar(**data)))


PAYLOADS = [
    _radar(0),
    _radar(1, range_std_m=None, bearing_std_rad=None),  # no noise: the sensor's default R
    _radar(2, elevation_rad=0.1, elevation_std_rad=0.01),
    _radar(3, range_rate_mps=-2.0, range_rate_std_mps=0.5),
    _radar(4, range_std_m=7.5),  # a noise not seen before
    m.encode(m.Measurement(sensor_id="cam1", t_ns=5, seq=0, data=m.Cartesian(pos_m=[1.0, 2.0], std_m=[3.0, 3.0]))),
    m.encode(m.Measurement(sensor_id="cam1", t_ns=5, seq=1, data=m.Cartesian(pos_m=[1.0, 2.0, 3.0]))),
    m.encode(m.Measurement(sensor_id="cam1", t_ns=5, seq=2, epoch=9,
                           data=m.Cartesian(pos_m=[1.0, 2.0], cov_m2=[4.0, 1.0, 1.0, 4.0]))),
    b"\x93\x01",  # malformed
    msgspec.msgpack.encode({"type": "measurement", "sensor_id": "cam1", "t_ns": 1, "seq": 0,
                            "data": {"type": "radar"}}),  # invalid
    msgspec.msgpack.encode({"type": "measurement", "v": 2, "sensor_id": "cam1", "t_ns": 1, "seq": 0,
                            "data": {"type": "cartesian", "pos_m": [1.0]}}),  # unsupported version
    msgspec.msgpack.encode({"type": "measurement", "sensor_id": "cam1", "t_ns": 1, "seq": 0,
                            "data": {"type": "cartesian", "pos_m": [math.inf, 1.0]}}),  # inf
    m.encode(m.Truth(target_id="t0", t_ns=1, state=[1.0], layout=["x"])),  # another message
]


def _same(a: Detection, b: Detection) -> None:
    assert (a.sensor_id, a.t_ns, a.seq, a.arrival_ns, a.epoch, a.radar_data) == \
        (b.sensor_id, b.t_ns, b.seq, b.arrival_ns, b.epoch, b.radar_data)
    assert a.z.dtype == b.z.dtype and a.z.tobytes() == b.z.tobytes()
    if a.R is None or b.R is None:
        assert a.R is None and b.R is None
    else:
        assert a.R.tobytes() == b.R.tobytes() and a.R.shape == b.R.shape
        assert (a.R is b.R) == (not a.R.flags.writeable)  # a shared diagonal R is the same array


def test_measurement_decoder_is_decode_measurement() -> None:
    dec = m.measurement_decoder()
    for p in PAYLOADS:
        try:
            one = m.decode_measurement(p)
        except m.MessageError:
            with pytest.raises(Exception):  # noqa: B017 (msgspec's own errors)
                dec(p)
        else:
            assert dec(p) == one


@pytest.mark.parametrize("arrival", [None, 123])
def test_codec_detections_is_codec_detection_of_each(arrival: int | None) -> None:
    codec = wire.Codec(NS)
    for order in (PAYLOADS, PAYLOADS[::-1], PAYLOADS * 2):
        got = codec.detections([(arrival, p) for p in order])
        for p, g in zip(order, got, strict=True):
            try:
                one = codec.detection(p, arrival)
            except m.MessageError:
                assert g is None
            else:
                assert g is not None
                _same(g, one)


class _OneByOne(wire.Codec):
    """The codec with every measurement decoded alone (the pipeline's one-sample path)."""

    def detections(self, samples):  # type: ignore[no-untyped-def]
        return [None] * len(samples)


class _Broken(wire.Codec):
    def detections(self, samples):  # type: ignore[no-untyped-def]
        raise RuntimeError("a decoder bug")


def _stream() -> list[tuple[str, bytes]]:
    stream, _, _ = _good_and_bad(NS)
    cam = m.meas_key(NS, GOOD_SENSOR)
    extra = [
        (m.meas_key(NS, "radar9"), stream[0][1]),  # key mismatch: cam1's measurement on another key
        (m.truth_key(NS, "t0"), m.encode(m.Truth(target_id="t0", t_ns=1, state=[1.0, 2.0], layout=["x", "y"]))),
        (m.truth_key(NS, "t1"), m.encode(m.Truth(target_id="t0", t_ns=1, state=[1.0], layout=["x"]))),
        (f"fusion/{NS}/elsewhere/x", stream[0][1]),  # not a measurement, input or truth key
        (m.input_key(NS, "u1"), m.encode(m.Input(source_id="u1", t_ns=1, seq=0, u=[1.0]))),
        (cam, msgspec.msgpack.encode({"type": "measurement", "v": 7, "sensor_id": GOOD_SENSOR, "t_ns": 1,
                                      "seq": 0, "data": {"type": "cartesian", "pos_m": [1.0]}})),
    ]
    for j, e in enumerate(extra):  # spread among the rest
        stream.insert(150 + 97 * j, e)
    return stream


def _run(codec: wire.Codec, stream: list[tuple[str, bytes]], batch: int, *, ahead: bool = False) -> tuple[object, ...]:
    """The stream through a pipeline in batches; `ahead`: each batch's measurements decoded
    before ingest, in three parts (as the service decodes a burst while it arrives)."""
    _, cfg = scenario_config("mix")
    cam = [s for s in cfg.tracker.sensors if s.id == GOOD_SENSOR]
    cfg = msgspec.structs.replace(cfg, tracker=msgspec.structs.replace(cfg.tracker, sensors=cam))
    pipe = Pipeline(Tracker(cfg.tracker), codec, max_future_wall_ns=10**12)
    records = [(200_000_000 + 1_000_000 * i, k, p) for i, (k, p) in enumerate(stream)]
    published, refused = [], []
    for i in range(0, len(records), batch):
        part = records[i:i + batch]
        cut = [0, len(part) // 3, len(part) // 2, len(part)]
        decoded = [d for a, b in itertools.pairwise(cut) for d in pipe.decoded(part[a:b])] if ahead else None
        out = pipe.ingest(part, decoded=decoded)
        published.extend(wire.estimate_message(e, layout=pipe.tracker.layout, model="m") for e in out.to_publish)
        refused.extend(out.result.refused)
    return pipe.counts(), published, refused, pipe.latency.stats(), pipe.gaps.report()


@pytest.mark.parametrize("batch", [1, 64, 5000])
def test_a_batch_decoded_at_once_is_the_one_sample_path(batch: int) -> None:
    """Every refusal reason at the edge and in the tracker, good data among them: the counts, the
    estimates, the refusals, latency and gaps are those of decoding every sample alone."""
    stream = _stream()
    fast = _run(wire.Codec(NS), stream, batch)
    assert fast == _run(_OneByOne(NS), stream, batch)
    assert fast == _run(_Broken(NS), stream, batch)  # a failing batch decode: each sample alone
    assert fast == _run(wire.Codec(NS), stream, batch, ahead=True)  # decoded before ingest, part by part
    assert fast == _run(_Broken(NS), stream, batch, ahead=True)
    c = fast[0]
    assert {"malformed", "invalid", "unknown_sensor", "bad_covariance", "future", "too_late", "key_mismatch",
            "unsupported_version"} <= set(c.refused)
    assert c.received == len(stream) and c.truth == 2  # a truth lacking a component is counted, not refused


def test_detections_share_the_diagonal_R() -> None:
    codec = wire.Codec(NS)
    a = codec.detections((1, p) for p in PAYLOADS[:8])
    b = codec.detections([(1, p) for p in PAYLOADS[:8]])
    for x, y, p in zip(a, b, PAYLOADS[:8], strict=True):
        assert x is not None and y is not None
        _same(x, wire.detection_of(m.decode_measurement(p), 1))
        if x.R is not None and not x.R.flags.writeable:
            assert x.R is y.R
    assert np.array_equal(a[0].R, np.diag([25.0, 0.003**2]))


def test_estimates_encoder_is_estimate_encoder_of_each() -> None:
    from fusion.tracking.results import Estimate

    rng = np.random.default_rng(3)
    layout = ("x", "vx", "y", "vy", "omega")
    ests = [Estimate(int(rng.integers(0, 2**40)), int(rng.integers(-2**62, 2**62)), "radar1",
                     int(rng.integers(-1, 2**40)), rng.normal(size=5), rng.normal(size=(5, 5)),
                     str(rng.choice(["confirmed", "tentative", "retracted", "predicted"])), int(rng.integers(0, 9)),
                     None if i % 3 else float(rng.normal()),
                     None if i % 2 else rng.dirichlet([1.0, 1.0]))
            for i in range(200)]
    ests.append(Estimate.retraction((7, 5, "cam1"), 3))  # no state: an empty layout
    one = wire.estimate_encoder(layout, "imm")
    many = wire.estimates_encoder(layout, "imm")(ests)
    assert many == [one(e) for e in ests]
    assert many == [m.encode(wire.estimate_message(e, layout=layout, model="imm")) for e in ests]
    assert wire.estimates_encoder(layout, "imm")([]) == []
