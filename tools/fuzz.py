"""A longer fuzz run of the decoder and the pipeline behind it, counting every input.

    python tools/fuzz.py --seconds 60 --seed 1

Inputs, from a seeded numpy Generator (the seed is printed; a run is reproducible):
  bytes     random bytes, 0-300 long
  mutated   a valid measurement's bytes with 1-4 bytes changed, cut or inserted
  shaped    msgpack maps shaped like a measurement with fields set to odd values (NaN, inf,
            huge ints, odd ids with newlines, wrong types, nested junk)
  nasty     valid measurements at the schema's edges (huge and tiny values, near-singular and
            indefinite covariances, extreme timestamps, 64-character ids), fed in batches through
            the pipeline and tracker of the mix scenario
Each input is decoded (and the nasty ones ingested); outcomes are counted: decoded, refused by
error type, refused by the pipeline by reason, and anything else that escaped (a bug: its type,
message and the input's kind are printed, with the first offending input in hex).
"""

from __future__ import annotations

import argparse
import collections
import logging
import math
import sys
import time
from pathlib import Path

import msgspec
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion import messages as m
from fusion.config import load_service_config
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker

ODD_FLOATS = [math.nan, math.inf, -math.inf, 0.0, -0.0, 5e-324, 1e-300, 1e15, -1e15, 1e16, 1e308, math.pi, 1.0]
ODD_INTS = [0, -1, 2**62, 2**62 + 1, -(2**62), 2**63 - 1, -(2**63), 2**64 - 1]
ODD_TEXT = ["cam1\n", "cam1 ", "a" * 64, "a" * 65, "", "cam1\x00", "radar1/x", "*", "measurement", "ç", "cam1\r"]
FIELDS = ["type", "v", "sensor_id", "t_ns", "seq", "data", "pos_m", "std_m", "cov_m2", "range_m", "bearing_rad",
          "range_std_m", "bearing_std_rad", "elevation_rad", "range_rate_mps", "range_rate_std_mps"]


def odd_value(rng: np.random.Generator, depth: int = 0) -> object:
    k = rng.integers(0, 9 if depth < 2 else 6)
    if k == 0:
        return ODD_FLOATS[rng.integers(len(ODD_FLOATS))]
    if k == 1:
        return ODD_INTS[rng.integers(len(ODD_INTS))]
    if k == 2:
        return ODD_TEXT[rng.integers(len(ODD_TEXT))]
    if k == 3:
        return float(rng.standard_normal() * 10.0 ** rng.integers(-20, 20))
    if k == 4:
        return None if rng.random() < 0.5 else bool(rng.integers(2))
    if k == 5:
        return bytes(rng.integers(0, 256, rng.integers(0, 16), dtype=np.uint8))
    if k == 6:
        return [odd_value(rng, depth + 1) for _ in range(rng.integers(0, 10))]
    return {FIELDS[rng.integers(len(FIELDS))]: odd_value(rng, depth + 1) for _ in range(rng.integers(0, 5))}


def valid(rng: np.random.Generator) -> m.Measurement:
    if rng.random() < 0.5:
        return m.Measurement(sensor_id="radar1", t_ns=int(rng.integers(0, 10**11)), seq=int(rng.integers(0, 10**6)),
                             data=m.Radar(range_m=float(rng.uniform(m.MIN_RANGE_M, 1e4)),
                                          bearing_rad=float(rng.uniform(-math.pi, math.pi))))
    return m.Measurement(sensor_id="cam1", t_ns=int(rng.integers(0, 10**11)), seq=int(rng.integers(0, 10**6)),
                         data=m.Cartesian(pos_m=rng.uniform(-3000, 3000, 2).tolist(), std_m=[3.0, 3.0]))


def mutated(rng: np.random.Generator) -> bytes:
    data = bytearray(m.encode(valid(rng)))
    for _ in range(rng.integers(1, 5)):
        i = int(rng.integers(0, max(len(data), 1)))
        op = rng.integers(3)
        if op == 0 and data:
            data[min(i, len(data) - 1)] = int(rng.integers(256))
        elif op == 1:
            del data[i:]
        else:
            data[i:i] = bytes(rng.integers(0, 256, rng.integers(1, 8), dtype=np.uint8))
    return bytes(data)


def shaped(rng: np.random.Generator) -> bytes:
    base: dict = msgspec.to_builtins(valid(rng))
    for _ in range(rng.integers(1, 4)):
        f = FIELDS[rng.integers(len(FIELDS))]
        top = f in ("type", "v", "sensor_id", "t_ns", "seq", "data") or not isinstance(base.get("data"), dict)
        (base if top else base["data"])[f] = odd_value(rng)
    try:
        return msgspec.msgpack.encode(base)
    except (OverflowError, TypeError):
        return msgspec.msgpack.encode({"type": "measurement"})


def nasty(rng: np.random.Generator, now_ns: int) -> m.Measurement:
    """A valid measurement at the schema's edges."""
    def big() -> float:
        return float(np.clip(rng.standard_normal() * 10.0 ** rng.integers(-300, 16), -1e15, 1e15))

    sid = ["radar1", "cam1", "x" * 64, "A.b-c_9"][rng.choice(4, p=[0.45, 0.45, 0.05, 0.05])]
    t = [int(rng.integers(-(2**62), 2**62)), 2**62, -(2**62), now_ns, now_ns - int(rng.integers(0, 3 * 10**9)),
         now_ns + int(rng.integers(0, 10**9))][rng.integers(6) if rng.random() < 0.3 else 3 + rng.integers(3)]
    if sid == "radar1" or (sid != "cam1" and rng.random() < 0.5):
        data: m.Cartesian | m.Radar = m.Radar(
            range_m=float(np.clip(10.0 ** rng.uniform(-1, 9), m.MIN_RANGE_M, m.MAX_RANGE_M)),
            bearing_rad=float(rng.uniform(-math.pi, math.pi)),
            range_rate_mps=big() if rng.random() < 0.3 else None)
    else:
        a, b = abs(big()) or 1.0, abs(big()) or 1.0
        c = math.sqrt(a * b) * (1 - [0.0, 1e-16, 1e-9][rng.integers(3)])
        cov = [a, c, c, b] if rng.random() < 0.5 else [-a, 0.0, 0.0, b]
        noise = rng.integers(3)
        data = m.Cartesian(pos_m=[big(), big()], std_m=[3.0, 3.0] if noise == 1 else None,
                           cov_m2=[min(max(x, -1e15), 1e15) for x in cov] if noise == 2 else None)
    return m.Measurement(sensor_id=sid, t_ns=t, seq=int(rng.integers(0, 2**62)), data=data)


def main(seconds: float, seed: int) -> int:
    logging.disable(logging.WARNING)  # refusals are counted here, not printed
    rng = np.random.default_rng(seed)
    cfg = load_service_config(Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "mix.toml")
    outcomes: collections.Counter[str] = collections.Counter()
    escaped: dict[str, tuple[str, bytes]] = {}
    tried: collections.Counter[str] = collections.Counter()
    pipe_refused: collections.Counter[str] = collections.Counter()
    gens = {"bytes": lambda: bytes(rng.integers(0, 256, rng.integers(0, 300), dtype=np.uint8)),
            "mutated": lambda: mutated(rng), "shaped": lambda: shaped(rng)}
    deadline = time.monotonic() + seconds
    pipe = Pipeline(Tracker(cfg.tracker), wire.Codec("demo"), max_future_wall_ns=3600 * 10**9)
    arrival = 10**12

    def add(p: Pipeline) -> None:
        c = p.counts()
        pipe_refused.update({r.value: n for r, n in c.refused.items()})
        pipe_refused["applied"] += c.applied
        pipe_refused["births"] += c.births
    while time.monotonic() < deadline:
        for kind, gen in gens.items():
            for _ in range(200):
                data = gen()
                tried[kind] += 1
                try:
                    m.decode_measurement(data)
                    outcomes["decoded"] += 1
                except m.MessageError as e:
                    outcomes[f"refused:{type(e).__name__}"] += 1
                except Exception as e:  # a decoder bug: counted and shown, the run goes on
                    k = f"{kind}:{type(e).__name__}"
                    outcomes[f"ESCAPED:{k}"] += 1
                    escaped.setdefault(k, (str(e), data))
        batch = []
        for i in range(int(rng.integers(1, 20))):
            msg = nasty(rng, arrival)
            batch.append((arrival + i, m.meas_key("demo", msg.sensor_id), m.encode(msg)))
        arrival += 10**8
        tried["nasty"] += len(batch)
        try:
            pipe.ingest(batch)
        except Exception as e:  # a tracker bug: counted and shown; start a fresh tracker
            k = f"nasty:{type(e).__name__}"
            outcomes[f"ESCAPED:{k}"] += len(batch)
            escaped.setdefault(k, (str(e), b"".join(r[2] for r in batch[:3])))
            add(pipe)
            pipe = Pipeline(Tracker(cfg.tracker), wire.Codec("demo"), max_future_wall_ns=3600 * 10**9)
            continue
    add(pipe)
    total = sum(tried.values())
    print(f"fuzz: seed {seed}, {seconds:.0f} s, {total} inputs tried: " + ", ".join(f"{k} {v}" for k, v in
                                                                                  sorted(tried.items())))
    for k, v in sorted(outcomes.items()):
        print(f"  decoder {k:40s} {v}")
    print("  pipeline: " + ", ".join(f"{k} {v}" for k, v in sorted(pipe_refused.items())))
    for k, (msg, data) in sorted(escaped.items()):
        print(f"  ESCAPED {k}: {msg}\n    first input: {data[:200].hex()}")
    return 1 if escaped else 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    raise SystemExit(main(a.seconds, a.seed))
