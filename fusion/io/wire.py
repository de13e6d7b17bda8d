"""Between the wire (fusion.messages) and the tracker: decode to Detections, encode Estimates
(the encoding side lives in fusion.io.wire_out, re-exported here)."""

from __future__ import annotations

import functools
from collections.abc import Iterable

import numpy as np

from fusion import messages as m
from fusion.io.wire_out import (  # noqa: F401 (re-exported: wire is the one import for both directions)
    encode_snapshot,
    encode_status,
    estimate_encoder,
    estimate_message,
    estimates_encoder,
    event_message,
    snapshot_of_encoded,
)
from fusion.tracking.detection import ControlInput, Detection

STREAM_SUFFIX = ".fstream"

status_key = m.status_key
snapshot_key = m.snapshot_key
all_measurements_key = m.all_meas_key
all_truth_key = m.all_truth_key
all_input_key = m.all_input_key


def is_measurement_key(key: str) -> bool:
    return "/meas/" in key


def detection_of(msg: m.Measurement, arrival_ns: int | None = None) -> Detection:
    """The tracker's view of a wire measurement: z and R in the sensor's measurement space (R None
    when the message carries no noise: the tracker then takes the sensor's configured one).
    R = diag(std^2) for per-axis standard deviations, shared read-only between the messages that
    carry the same ones (diagonal_R). The two common shapes (a 2-D radar return, a position with
    per-axis std) are built without the general path's lists."""
    d = msg.data
    R: np.ndarray | None = None
    if type(d) is m.Radar:
        if d.elevation_rad is None and d.range_rate_mps is None:
            z = np.array((d.range_m, d.bearing_rad), dtype=np.float64)
            if d.range_std_m is not None:
                R = diagonal_R((d.range_std_m, d.bearing_std_rad))  # type: ignore[arg-type]
            return Detection(msg.sensor_id, msg.t_ns, msg.seq, z, R, arrival_ns, msg.epoch, True)
        vals = [d.range_m, d.bearing_rad]
        std = [d.range_std_m, d.bearing_std_rad]
        if d.elevation_rad is not None:
            vals.append(d.elevation_rad)
            std.append(d.elevation_std_rad)
        if d.range_rate_mps is not None:
            vals.append(d.range_rate_mps)
            std.append(d.range_rate_std_mps)
        z = np.array(vals, dtype=np.float64)
        if d.has_noise:
            R = diagonal_R(tuple(std))  # type: ignore[arg-type]
        return Detection(msg.sensor_id, msg.t_ns, msg.seq, z, R, arrival_ns, msg.epoch, True)
    z = np.array(d.pos_m, dtype=np.float64)
    if d.std_m is not None:
        R = diagonal_R(tuple(d.std_m))
    elif d.cov_m2 is not None:
        k = z.shape[0]
        R = np.array(d.cov_m2, dtype=np.float64).reshape(k, k)
    return Detection(msg.sensor_id, msg.t_ns, msg.seq, z, R, arrival_ns, msg.epoch, False)


_DIAGONALS: dict[tuple[float, ...], np.ndarray] = {}
_DIAGONALS_MAX = 4096


def diagonal_R(std: tuple[float, ...]) -> np.ndarray:
    """diag(std^2), read-only, one array per distinct std (sensors repeat theirs): a dict look-up
    instead of three numpy calls per message. The memo is emptied when it reaches 4096 entries
    (a sender whose stds vary per message then costs what it did without it)."""
    R = _DIAGONALS.get(std)
    if R is None:
        if len(_DIAGONALS) >= _DIAGONALS_MAX:
            _DIAGONALS.clear()
        R = np.diag(np.square(np.array(std, dtype=np.float64)))
        R.flags.writeable = False
        _DIAGONALS[std] = R
    return R


class Codec:
    """The pipeline's codec for namespace `ns` (see fusion.pipeline.Codec)."""

    def __init__(self, ns: str) -> None:
        self.ns = ns
        self._keys: dict[str, tuple[str, str]] = {}  # key -> (kind, id): a few keys, seen per sample

    def _parsed(self, key: str) -> tuple[str, str]:
        p = self._keys.get(key)
        if p is None:
            if len(self._keys) >= 4096:
                self._keys.clear()
            p = self._keys[key] = (m.key_kind(key), key.rsplit("/", 1)[-1])
        return p

    def kind(self, key: str) -> str:
        return self._parsed(key)[0]

    def key_id(self, key: str) -> str:
        return self._parsed(key)[1]

    def detection(self, payload: bytes, arrival_ns: int | None = None) -> Detection:
        """Raises MalformedMessageError or InvalidMessageError (fusion.errors) for bad bytes."""
        return detection_of(m.decode_measurement(payload), arrival_ns)

    def detections(self, samples: Iterable[tuple[int | None, bytes]]) -> list[Detection | None]:
        """[detection(payload, arrival_ns) for (arrival_ns, payload) in samples], in one loop,
        with None where `detection` would raise (call it on that payload for the error). The
        same Detections (the same shared R arrays): the two shapes the shipped sensors send (a
        2-D radar return with its noise, a 2-D position with per-axis std) are built inline,
        the rest by detection_of. Each message is dropped once converted (a list of them would
        outlive the collector's young generation: measured slower than one at a time)."""
        dec = m.measurement_decoder()
        out: list[Detection | None] = []
        add = out.append
        radar, cart, memo, array, f64 = m.Radar, m.Cartesian, _DIAGONALS, np.array, np.float64
        for a, p in samples:
            try:
                msg = dec(p)
            except Exception:
                add(None)
                continue
            d = msg.data
            if type(d) is radar:
                rs = d.range_std_m
                if rs is not None and d.elevation_rad is None and d.range_rate_mps is None:
                    R = memo.get((rs, d.bearing_std_rad))  # type: ignore[arg-type]
                    if R is not None:
                        add(Detection(msg.sensor_id, msg.t_ns, msg.seq, array((d.range_m, d.bearing_rad), dtype=f64),
                                      R, a, msg.epoch, True))
                        continue
            elif type(d) is cart and d.cov_m2 is None and d.std_m is not None:
                R = memo.get(tuple(d.std_m))
                if R is not None:
                    add(Detection(msg.sensor_id, msg.t_ns, msg.seq, array(d.pos_m, dtype=f64), R, a, msg.epoch, False))
                    continue
            add(detection_of(msg, a))  # the general path (and the first message of each noise)
        return out

    def control(self, payload: bytes, arrival_ns: int | None = None) -> ControlInput:
        msg = m.decode_input(payload)
        return ControlInput(msg.source_id, msg.t_ns, msg.seq, np.array(msg.u, dtype=np.float64), arrival_ns)

    def truth(self, payload: bytes, layout: tuple[str, ...]) -> tuple[str, int, np.ndarray] | None:
        return truth_in_layout(m.decode_truth(payload), layout)


def truth_in_layout(msg: m.Truth, layout: tuple[str, ...]) -> tuple[str, int, np.ndarray] | None:
    """The truth's components reordered into the tracker's layout (None if one is missing)."""
    by_name = dict(zip(msg.layout, msg.state, strict=True))
    if not all(n in by_name for n in layout):
        return None
    return msg.target_id, msg.t_ns, np.array([by_name[n] for n in layout], dtype=np.float64)


@functools.lru_cache(maxsize=64)
def _tracks_prefix(ns: str) -> str:
    return m.track_key(ns, 0)[:-1]  # the namespace checked once


def track_key(ns: str, track_id: int) -> str:
    """fusion.messages.track_key, the namespace's prefix built once."""
    return _tracks_prefix(ns) + str(int(track_id))
