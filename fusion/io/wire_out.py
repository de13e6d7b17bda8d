"""The wire's outbound side: the tracker's Estimates and TrackEvents, the service's status and
snapshot, as fusion.messages bytes (moved out of fusion.io.wire, which re-exports them)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict
from typing import Any

import msgspec

from fusion import messages as m
from fusion.tracking.results import Estimate, TrackEvent


def estimate_message(e: Estimate, *, layout: tuple[str, ...], model: str) -> m.Estimate:
    return _estimate(e, list(layout), model)


def _estimate(e: Estimate, names: list[str], model: str) -> m.Estimate:
    """The wire Estimate; `names` (the layout) is shared by the messages of one encoder."""
    mu = e.mode_probabilities
    return m.Estimate(
        track_id=e.track_id, t_ns=e.t_ns, sensor_id=e.sensor_id, seq=e.seq if e.seq > 0 else 0, state=e.x.tolist(),
        cov=e.P.ravel().tolist(), layout=names if e.x.size else [], model=model,
        status=e.status,  # type: ignore[arg-type]
        revision=e.revision, nis=e.nis, mode_probabilities=None if mu is None else mu.tolist(),
    )


def event_message(ev: TrackEvent) -> m.Event:
    return m.Event(track_id=ev.track_id, t_ns=ev.t_ns, kind=ev.kind.value,  # type: ignore[arg-type]
                   reason=None if ev.reason is None else ev.reason.value, withdrawn=ev.retracted)


def _positional(cls: type[msgspec.Struct]) -> type[msgspec.Struct]:
    """A struct that encodes exactly as `cls` (same tag, fields in the same order, the same
    defaults omitted) but is built from positional arguments, 0.4 us cheaper per message than
    keywords: for encoding only. A field with a default factory (`v`) is a required one here,
    so it is always given, as the factory's value always is on the wire."""
    spec: list[Any] = []
    for f in msgspec.structs.fields(cls):
        if f.default is msgspec.NODEFAULT:  # required, or a factory
            spec.append((f.name, Any))
        else:
            spec.append((f.name, Any, f.default))
    cfg = cls.__struct_config__
    return msgspec.defstruct(f"{cls.__name__}Out", spec, tag=cfg.tag, tag_field=cfg.tag_field, frozen=True,
                             omit_defaults=cfg.omit_defaults)


_EstimateOut = _positional(m.Estimate)


def estimate_encoder(layout: tuple[str, ...], model: str) -> Callable[[Estimate], bytes]:
    """e -> m.encode(estimate_message(e, layout=layout, model=model)), the same bytes, built
    positionally (_EstimateOut) with the tolist of each array once."""
    names = list(layout)
    encode, out, v = m.encode, _EstimateOut, m.SCHEMA_VERSION

    def enc(e: Estimate) -> bytes:
        mu = e.mode_probabilities
        x = e.x
        return encode(out(v, e.track_id, e.t_ns, e.sensor_id, e.seq if e.seq > 0 else 0, x.tolist(),  # type: ignore[arg-type]
                          e.P.ravel().tolist(), names if x.size else [], model, e.status, e.revision, e.nis,
                          None if mu is None else mu.tolist()))

    return enc


def estimates_encoder(layout: tuple[str, ...], model: str) -> Callable[[Sequence[Estimate]], list[bytes]]:
    """es -> [estimate_encoder(layout, model)(e) for e in es], the same bytes, in one loop."""
    names = list(layout)
    encode, out, v = m.encode, _EstimateOut, m.SCHEMA_VERSION

    def enc_all(es: Sequence[Estimate]) -> list[bytes]:
        return [encode(out(v, e.track_id, e.t_ns, e.sensor_id, e.seq if e.seq > 0 else 0, e.x.tolist(),  # type: ignore[arg-type]
                           e.P.ravel().tolist(), names if e.x.size else [], model, e.status, e.revision, e.nis,
                           None if e.mode_probabilities is None else e.mode_probabilities.tolist()))
                for e in es]

    return enc_all


def encode_status(status: dict[str, Any]) -> bytes:
    c = status["counts"]
    msg = m.ServiceStatus(
        uptime_s=status["uptime_s"], counts=m.Counts(**c), tracks=status["tracks"],
        latency={k: m.LatencyStats(**asdict(v)) for k, v in status["latency"].items()},
        recording=status["recording"], recording_bytes=status["recording_bytes"], queue_depth=status["queue_depth"],
        gaps={k: m.SeqGapStats(**v) for k, v in status.get("gaps", {}).items()},
        zenoh=m.ZenohLink(**status["zenoh"]) if status.get("zenoh") else None,
        checkpoint=m.CheckpointStatus(**status["checkpoint"]) if status.get("checkpoint") else None,
        recording_error=status.get("recording_error"), recording_queue=status.get("recording_queue", 0),
    )
    return m.encode(msg)


def encode_snapshot(estimates: list[m.Estimate]) -> bytes:
    return m.encode(m.Snapshot(estimates=estimates))


_SNAPSHOT_HEAD = m.encode(m.Snapshot(estimates=[]))[:-1]  # the map up to the estimates' array header


def snapshot_of_encoded(estimates: list[bytes]) -> bytes:
    """encode_snapshot's bytes from estimates already encoded (m.encode of each m.Estimate):
    the Snapshot map with the msgpack array header of len(estimates) (fixarray below 16,
    array16 below 2^16, else array32) and the estimates' bytes joined, with no re-encoding."""
    n = len(estimates)
    if n < 16:
        head = bytes((0x90 | n,))
    elif n < 1 << 16:
        head = b"\xdc" + n.to_bytes(2, "big")
    else:
        head = b"\xdd" + n.to_bytes(4, "big")
    return b"".join([_SNAPSHOT_HEAD, head, *estimates])
