"""Hostile and valid-but-nasty wire messages, as hypothesis strategies (tests/security)."""

from __future__ import annotations

import math

import msgspec
from hypothesis import strategies as st

from fusion import messages as m

SENSORS = ("radar1", "cam1")  # the mix scenario's
FIELDS = ("type", "v", "sensor_id", "t_ns", "seq", "data", "pos_m", "std_m", "cov_m2", "range_m", "bearing_rad",
          "range_std_m", "bearing_std_rad", "elevation_rad", "range_rate_mps", "target_id", "state", "layout")

# numbers at and around every bound the schema has, and the awkward ones in between
nasty_floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e-300, 1e-30, 1e15, -1e15, 1e15 * (1 + 1e-16), 1e16, math.pi,
                     -math.pi, math.pi + 1e-15, math.pi / 2, 2.0**53, 1.0]),
)
nasty_ints = st.one_of(st.integers(-(2**63), 2**64 - 1),  # what msgpack can carry
                       st.sampled_from([0, -1, 2**62, 2**62 + 1, -(2**62), 2**63 - 1, -(2**63), 2**64 - 1]))
odd_text = st.one_of(st.text(max_size=80), st.sampled_from(["cam1\n", "cam1 ", "a" * 64, "a" * 65, "", "cam1\x00",
                                                            "radar1/x", "*", "measurement"]))

msgpack_values = st.recursive(
    st.one_of(st.none(), st.booleans(), nasty_ints, nasty_floats, odd_text, st.binary(max_size=32)),
    lambda inner: st.one_of(st.lists(inner, max_size=6),
                            st.dictionaries(st.one_of(st.sampled_from(FIELDS), odd_text), inner, max_size=6)),
    max_leaves=20,
)


@st.composite
def measurement_like(draw) -> bytes:
    """A map that looks like a measurement, with any field changed to anything."""
    base: dict = {"type": "measurement", "v": 1, "sensor_id": "cam1", "t_ns": 10**9, "seq": 1,
                  "data": {"type": "cartesian", "pos_m": [1.0, 2.0]}}
    for k in draw(st.lists(st.sampled_from(FIELDS), max_size=4)):
        base[k] = draw(msgpack_values)
    if draw(st.booleans()):
        base["data"] = draw(st.dictionaries(st.sampled_from(FIELDS), msgpack_values, max_size=5)) | {
            "type": draw(st.sampled_from(["cartesian", "radar", "x"]))}
    return msgspec.msgpack.encode(base)


@st.composite
def mutated(draw) -> bytes:
    """A valid measurement's bytes, cut, extended or with bytes changed."""
    data = bytearray(m.encode(m.Measurement(sensor_id="radar1", t_ns=10**9, seq=3, data=m.Radar(
        range_m=100.0, bearing_rad=0.1, range_std_m=1.0, bearing_std_rad=0.01))))
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "cut", "insert"]))
        i = draw(st.integers(0, max(len(data) - 1, 0)))
        if op == "flip" and data:
            data[i] = draw(st.integers(0, 255))
        elif op == "cut":
            del data[i:]
        else:
            data[i:i] = draw(st.binary(min_size=1, max_size=8))
    return bytes(data)


# ---- valid but nasty: what the schema accepts at its edges -------------------------------------
finite = st.one_of(st.floats(-1e15, 1e15), st.sampled_from([0.0, 5e-324, -5e-324, 1e-300, 1e15, -1e15, 1e-9]))
positive = st.one_of(st.floats(5e-324, 1e15), st.sampled_from([5e-324, 1e-300, 1e-12, 1e15]))
ranges = st.one_of(st.floats(m.MIN_RANGE_M, m.MAX_RANGE_M), st.sampled_from([m.MIN_RANGE_M, 1.0, m.MAX_RANGE_M]))
bearing = st.floats(-math.pi, math.pi)
times = st.one_of(st.integers(-(2**62), 2**62), st.integers(0, 10**11), st.sampled_from([0, 2**62, -(2**62)]))
ids = st.one_of(st.sampled_from(SENSORS), st.from_regex(r"[A-Za-z0-9_.\-]{1,64}", fullmatch=True))


@st.composite
def covariance(draw, d: int) -> list[float]:
    """Row-major d x d: near-singular, singular, indefinite, huge, tiny or asymmetric."""
    kind = draw(st.sampled_from(["near_singular", "singular", "indefinite", "scaled", "asymmetric"]))
    a, b = draw(positive), draw(positive)
    if d == 1:
        return [draw(st.sampled_from([a, -a, 0.0]))]
    eps = draw(st.sampled_from([0.0, 1e-16, 1e-12, 1e-6]))
    c = math.sqrt(a * b) * (1 - eps) if kind in ("near_singular", "singular") else draw(finite)
    M = [[0.0] * d for _ in range(d)]
    for i in range(d):
        M[i][i] = a if i % 2 == 0 else b
    M[0][1] = M[1][0] = c
    if kind == "asymmetric":
        M[1][0] = c + 1.0
    if kind == "indefinite":
        M[0][0] = -a
    return [min(max(x, -1e15), 1e15) for row in M for x in row]


# A radar return's own noise can make a new track's covariance singular (range std 187 m with a
# bearing std of 1e-6 rad at 1 m: condition number ~1e16) and the error escapes the pipeline:
# see test_hostile_properties' xfail. Radar returns here use the sensor's configured noise.
sane_std = st.one_of(st.floats(1e-3, 1e6), st.sampled_from([1e-3, 1e6]))


@st.composite
def nasty_measurement(draw) -> m.Measurement:
    sid = draw(ids)
    # a radar's key carries radar data and a camera's Cartesian (a Cartesian measurement on a
    # radar sensor is read as range and bearing: see test_hostile_properties' xfail)
    if sid == "cam1" or (sid != "radar1" and draw(st.booleans())):
        d = 2
        noise = draw(st.sampled_from(["none", "std", "cov"]))
        data: m.Cartesian | m.Radar = m.Cartesian(
            pos_m=[draw(finite) for _ in range(d)],
            std_m=[draw(sane_std) for _ in range(d)] if noise == "std" else None,
            cov_m2=draw(covariance(d)) if noise == "cov" else None)
    else:
        noisy = False
        rr = draw(st.booleans())
        data = m.Radar(range_m=draw(ranges), bearing_rad=draw(bearing),
                       range_std_m=draw(sane_std) if noisy else None,
                       bearing_std_rad=draw(sane_std) if noisy else None,
                       range_rate_mps=draw(finite) if rr else None,
                       range_rate_std_mps=draw(sane_std) if rr and noisy else None)
    return m.Measurement(sensor_id=sid, t_ns=draw(times), seq=draw(st.integers(0, 2**62)), data=data)
