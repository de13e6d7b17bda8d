"""The load of the end-to-end benchmark: a scene, its wire messages, and the two helper processes
(a publisher and a counting subscriber) that run beside `fusion serve`.

Scene: T 2-D targets on a jittered grid 10 km wide, 2.8-12.8 km north of radar1 (500, -800),
flying away from the radar (heading = the radar's bearing +- 0.3 rad) at 5-20 m/s, with the
publishers' white-noise acceleration (density 0.0025 m^2/s^3): nobody comes near the radar
and targets do not cross, however long a soak runs. Time advances in 50 ms ticks: radar1 scans
at ticks 0, 2, 4, ... (10 Hz; one return per target, all with the scan's time), cam1 at ticks
1, 5, 9, ... (5 Hz). Measurements carry the configuration's noise (radar 5 m and 3 mrad, camera
3 m), as fusion.messages.Measurement in msgpack: 15 messages per target per second.

Processes (multiprocessing, spawn): `publisher_main` serves commands on a pipe (prepare, connect,
blast, paced, disconnect), so the same prepared messages go to the baseline and to the service;
`counter_main` is the baseline's trivial subscriber (a peer listening on 127.0.0.1, counting).
"""

from __future__ import annotations

import math
import struct
import time
from collections import deque
from collections.abc import Iterator
from typing import Any

import numpy as np

from fusion import messages as m

TICK_NS = 50_000_000
RADAR_POS = np.array([500.0, -800.0])
RADAR_STD = (5.0, 0.003)  # range m, bearing rad (configs/service.toml)
CAM_STD = 3.0
Q_PSD = 0.0025  # m^2/s^3, as configs/service.toml's modes and publishers.truth.MIX_Q**2
SENSORS = ("radar1", "cam1")
MSGS_PER_TARGET_S = 15  # 10 radar + 5 camera


class Scene:
    """T targets; `ticks(t0_ns)` yields (t_ns, sensor index, payloads) scan by scan, in time order.
    north_m moves the whole scene north (the primer's targets, far from the measured ones)."""

    def __init__(self, n_targets: int, seed: int, *, north_m: float = 0.0) -> None:
        rng = self.rng = np.random.default_rng(seed)
        side = math.ceil(math.sqrt(n_targets))
        cell = 10_000.0 / side
        i = np.arange(n_targets)
        x = -5000.0 + (i % side + 0.5) * cell + rng.uniform(-0.25, 0.25, n_targets) * cell
        y = north_m + 2000.0 + (i // side + 0.5) * cell + rng.uniform(-0.25, 0.25, n_targets) * cell
        heading = np.arctan2(y - RADAR_POS[1], x - RADAR_POS[0]) + rng.uniform(-0.3, 0.3, n_targets)
        speed = rng.uniform(5.0, 20.0, n_targets)
        self.pos = np.stack([x, y], axis=1)
        self.vel = np.stack([speed * np.cos(heading), speed * np.sin(heading)], axis=1)
        dt = TICK_NS / 1e9
        # exact discrete white-noise-acceleration increments per axis: [[dt^3/3, dt^2/2], [dt^2/2, dt]] * q
        self.L = np.linalg.cholesky(Q_PSD * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]))
        self.n = n_targets
        self.seq = [0, 0]

    def _advance(self) -> None:
        dt = TICK_NS / 1e9
        w = self.rng.standard_normal((2, self.n, 2)) @ self.L.T  # (axis, target, [dpos, dvel])
        self.pos += self.vel * dt + w[:, :, 0].T
        self.vel += w[:, :, 1].T

    def _encode(self, sensor: int, t_ns: int) -> list[bytes]:
        rng, n, seq0 = self.rng, self.n, self.seq[sensor]
        self.seq[sensor] += n
        if sensor == 0:
            d = self.pos - RADAR_POS
            r = np.hypot(d[:, 0], d[:, 1]) + rng.normal(0.0, RADAR_STD[0], n)
            b = np.arctan2(d[:, 1], d[:, 0]) + rng.normal(0.0, RADAR_STD[1], n)
            b = (b + math.pi) % (2 * math.pi) - math.pi
            rs, bs = RADAR_STD
            datas: list[Any] = [m.Radar(range_m=ri, bearing_rad=bi, range_std_m=rs, bearing_std_rad=bs)
                                for ri, bi in zip(r.tolist(), b.tolist(), strict=True)]
        else:
            z = (self.pos + rng.normal(0.0, CAM_STD, (n, 2))).tolist()
            datas = [m.Cartesian(pos_m=zi, std_m=[CAM_STD, CAM_STD]) for zi in z]
        sid = SENSORS[sensor]
        return [m.encode(m.Measurement(sensor_id=sid, t_ns=t_ns, seq=seq0 + j, data=dj)) for j, dj in enumerate(datas)]

    def ticks(self, t0_ns: int) -> Iterator[tuple[int, int, list[bytes]]]:
        k = 0
        while True:
            t = t0_ns + k * TICK_NS
            if k % 2 == 0:
                yield t, 0, self._encode(0, t)
            elif k % 4 == 1:
                yield t, 1, self._encode(1, t)
            self._advance()
            k += 1


def dense_ticks(n_targets: int, n_messages: int, seed: int, base_ns: int) -> Iterator[tuple[int, int, list[bytes]]]:
    """The dense scene, as Scene.ticks yields its scans (t_ns from base_ns on, sensor index,
    payloads) until n_messages are out: the mix's sensors (configs/scenarios/mix.toml: radar1 Pd
    0.95 with 2 false returns a scan, cam1 Pd 0.9 with 1, over 6 x 6 km; no latency, drop-outs or
    duplicates) over publishers.truth.mix_truth's targets (two crossing, one turning, the rest
    from a ring 1-3 km out heading inwards at 5-25 m/s, so their gates meet as they converge),
    as bench.late_data and the tracker's dense-scene figures use them."""
    import msgspec

    from publishers.sensors import simulate_sensor
    from publishers.spec import LatencySpec, load_scenario_file, scenario_path
    from publishers.truth import mix_truth

    spec = load_scenario_file(scenario_path("mix")).scenario
    per_s = n_targets * sum(s.rate_hz * s.pd for s in spec.sensors) + sum(s.rate_hz * s.clutter_per_scan
                                                                         for s in spec.sensors)
    duration_s = math.ceil(n_messages / per_s * 1.1) + 1.0
    truths = mix_truth(n_targets=n_targets, dt_s=spec.dt_s, duration_s=duration_s, seed=seed)
    rng = np.random.default_rng([seed, 3])
    scans: dict[tuple[int, int], list[bytes]] = {}
    for sensor in spec.sensors:
        quiet = msgspec.structs.replace(sensor, latency=LatencySpec(), dropout=0.0, duplicate=0.0)
        for e in simulate_sensor(quiet, truths, rng):
            msg = msgspec.structs.replace(e.msg, t_ns=base_ns + e.msg.t_ns)  # > 2^32: a uint64, as restamp wants
            scans.setdefault((msg.t_ns, SENSORS.index(sensor.id)), []).append(m.encode(msg))
    for (t, s), payloads in sorted(scans.items()):
        yield t, s, payloads


LATE_WARM_SCANS = 30  # scans sent in order before any is held back (the tracks' births and confirmation)
LATE_MAX_SCANS = 25  # a held-back measurement goes out 1 to this many scans late (1.7 s: inside the 2 s window)


class Prepared:
    """The first n_messages of a scene, encoded once, re-stamped in place before each blast:
    `restamp(t0_ns)` moves every t_ns by the same amount (msgpack uint64 after the "t_ns" key),
    so the stream starts at t0_ns (the service's clock needs sensor times near arrival times).
    `dense`: dense_ticks' scene instead of Scene's grid. `late`: the fraction of measurements
    (after the first LATE_WARM_SCANS scans) sent late, each after the scan 1 to LATE_MAX_SCANS
    scans after its own (uniform; seeded by `seed`), as bench.late_data holds them back; the
    rest in time order."""

    def __init__(self, n_targets: int, n_messages: int, *, seed: int, late: float = 0.0, dense: bool = False) -> None:
        self.sensor: list[int] = []
        self.buf: list[bytearray] = []
        self.rel_ns: list[int] = []
        self.t0_ns = base = 1 << 60
        scans: list[tuple[int, int, list[bytes]]] = []
        n = 0
        ticks = dense_ticks(n_targets, n_messages, seed, base) if dense else Scene(n_targets, seed).ticks(base)
        for t, s, payloads in ticks:
            take = payloads[: n_messages - n]
            scans.append((t - base, s, take))
            n += len(take)
            if n >= n_messages:
                break
        for rel, s, payload in _arrival_order(scans, late, seed):
            self.sensor.append(s)
            self.buf.append(bytearray(payload))
            self.rel_ns.append(rel)
        self.off = [b.index(b"\xa4t_ns\xcf") + 6 for b in self.buf]

    def restamp(self, t0_ns: int) -> None:
        for b, off, rel in zip(self.buf, self.off, self.rel_ns, strict=True):
            struct.pack_into(">Q", b, off, t0_ns + rel)
        self.t0_ns = t0_ns


def _arrival_order(scans: list[tuple[int, int, list[bytes]]], late: float, seed: int
                   ) -> list[tuple[int, int, bytes]]:
    """(rel_ns, sensor, payload) in the order sent: each scan's measurements, then those held back
    that are due after it (in the order they were held); what is due after the last scan last."""
    rng = np.random.default_rng([seed, 7])
    due: dict[int, list[tuple[int, int, bytes]]] = {}
    out: list[tuple[int, int, bytes]] = []
    for k, (rel, s, payloads) in enumerate(scans):
        for p in payloads:
            if late > 0.0 and k >= LATE_WARM_SCANS and rng.random() < late:
                due.setdefault(k + int(rng.integers(1, LATE_MAX_SCANS + 1)), []).append((rel, s, p))
            else:
                out.append((rel, s, p))
        out.extend(due.pop(k, []))
    for k in sorted(due):
        out.extend(due[k])
    return out


# ---- the publisher process -----------------------------------------------------------------------
def publisher_main(conn: Any, namespace: str) -> None:
    """Serve the parent's commands on `conn` until ("quit", None); every reply is ("ok", value)
    or ("error", text). Congestion control BLOCK on both sensors' keys."""
    import zenoh

    from fusion.io.zenoh_bus import session_config, wait_for_match

    prepared: Prepared | None = None
    session: Any = None
    pubs: list[Any] = []
    try:
        while True:
            cmd, arg = conn.recv()
            if cmd == "quit":
                return
            try:
                if cmd == "prepare":
                    t = time.perf_counter()
                    prepared = Prepared(arg["targets"], arg["messages"], seed=arg["seed"], late=arg.get("late", 0.0),
                                        dense=arg.get("dense", False))
                    reply: Any = {"encode_s": time.perf_counter() - t, "bytes": sum(len(p) for p in prepared.buf),
                                  "sensor_s": prepared.rel_ns[-1] / 1e9}
                elif cmd == "connect":
                    if session is not None:  # left open by a run that failed
                        session.close()
                        session = None
                    session = zenoh.open(session_config(mode="client", connect=[arg]))
                    bl = zenoh.CongestionControl.BLOCK
                    pubs = [session.declare_publisher(m.meas_key(namespace, s), congestion_control=bl)
                            for s in SENSORS]
                    if not all(wait_for_match(p, timeout_s=15.0) for p in pubs):
                        raise TimeoutError("no subscriber matched within 15 s")
                    reply = None
                elif cmd == "blast":  # the prepared messages, sensor times from now on
                    assert prepared is not None
                    prepared.restamp(time.time_ns() + 1_000_000_000)  # re-stamping takes a while on a busy machine
                    put = [p.put for p in pubs]
                    t0 = time.time_ns()
                    for s, payload in zip(prepared.sensor, prepared.buf, strict=True):
                        put[s](payload)
                    reply = {"sent": len(prepared.buf), "t0_ns": t0, "t1_ns": time.time_ns()}
                elif cmd == "prime":  # 3 targets 50 km north, 6 scans (4 radar, 2 camera), at once
                    put = [p.put for p in pubs]
                    ticks = Scene(3, 99, north_m=50_000.0).ticks(time.time_ns())
                    sent = 0
                    for _ in range(6):
                        _t, s, payloads = next(ticks)
                        for payload in payloads:
                            put[s](payload)
                        sent += len(payloads)
                    reply = {"sent": sent}
                elif cmd == "paced":
                    reply = _paced(pubs, **arg)
                elif cmd == "disconnect":
                    for p in pubs:
                        p.undeclare()
                    pubs = []
                    session.close()
                    session = None
                    reply = None
                else:
                    raise ValueError(f"unknown command {cmd!r}")
                conn.send(("ok", reply))
            except Exception as e:  # report to the parent, which raises it
                conn.send(("error", f"{type(e).__name__}: {e}"))
    finally:
        if session is not None:
            session.close()


def _paced(pubs: list[Any], *, targets: int, seed: int, start_ns: int, duration_s: float,
           late: float = 0.0) -> dict[str, Any]:
    """Each scan as one burst at its due time (its t_ns, wall clock), for duration_s. Scans are
    encoded a few ahead, right after a burst, never between a due time and its burst. `late`:
    the fraction of measurements held back (after LATE_WARM_SCANS scans) and sent at the end of
    the burst of a scan 1 to LATE_MAX_SCANS scans later (as Prepared's); what is still held at
    the end is not sent."""
    put = [p.put for p in pubs]
    end_ns = start_ns + round(duration_s * 1e9)
    ticks = Scene(targets, seed).ticks(start_ns)
    ahead = deque(next(ticks) for _ in range(6))
    late_ns: list[int] = []
    burst_ns: list[int] = []
    sent = 0
    rng = np.random.default_rng([seed, 7])
    due: dict[int, list[tuple[int, bytes]]] = {}
    k = 0
    while ahead[0][0] < end_ns:
        t, s, payloads = ahead.popleft()
        if late > 0.0 and k >= LATE_WARM_SCANS:
            held = rng.random(len(payloads)) < late
            for p in [p for p, h in zip(payloads, held.tolist(), strict=True) if h]:
                due.setdefault(k + int(rng.integers(1, LATE_MAX_SCANS + 1)), []).append((s, p))
            payloads = [p for p, h in zip(payloads, held.tolist(), strict=True) if not h]
        wait = (t - time.time_ns()) / 1e9
        if wait > 0:
            time.sleep(wait)
        b0 = time.time_ns()
        for p in payloads:
            put[s](p)
        for s_late, p in due.get(k, ()):
            put[s_late](p)
        sent += len(due.pop(k, ()))
        k += 1
        b1 = time.time_ns()
        late_ns.append(b0 - t)
        burst_ns.append(b1 - b0)
        sent += len(payloads)
        ahead.append(next(ticks))
    late = np.array(late_ns) / 1e6
    burst = np.array(burst_ns) / 1e6
    return {"sent": sent, "scans": len(late_ns), "t1_ns": time.time_ns(),
            "late_p50_ms": float(np.median(late)), "late_max_ms": float(late.max()),
            "burst_p50_ms": float(np.median(burst)), "burst_max_ms": float(burst.max())}


# ---- the baseline's subscriber process -----------------------------------------------------------
def counter_main(endpoint: str, key: str, expect: int, timeout_s: float, out: Any) -> None:
    """A peer listening on `endpoint` that counts samples on `key`; puts ("ready",) once declared,
    then ("done", count, first_ns, last_ns) when `expect` arrived or timeout_s passed."""
    import zenoh

    from fusion.io.zenoh_bus import session_config

    state = [0, 0, 0]

    def on_sample(_sample: Any) -> None:
        now = time.time_ns()
        if state[0] == 0:
            state[1] = now
        state[0] += 1
        state[2] = now

    try:
        session = zenoh.open(session_config(mode="peer", listen=[endpoint]))
    except Exception as e:
        out.put(("error", f"{type(e).__name__}: {e}"))
        return
    try:
        sub = session.declare_subscriber(key, on_sample)
        out.put(("ready",))
        deadline = time.monotonic() + timeout_s
        while state[0] < expect and time.monotonic() < deadline:
            time.sleep(0.005)
        out.put(("done", state[0], state[1], state[2]))
        sub.undeclare()
    finally:
        session.close()
