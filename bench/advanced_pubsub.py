"""What zenoh's advanced publisher and subscriber cost: `python -m bench.advanced_pubsub`.

Two in-process sessions on 127.0.0.1 (a listening peer, a client), N measurement-sized payloads
(the encoded size of a real cam1 measurement) put back to back with congestion control BLOCK;
the rate is N over the time from the first put to the last sample counted by the subscriber's
callback. Three ways, interleaved, repeated: plain publisher -> plain subscriber (the baseline,
what the service used before), plain publisher -> RecoveringSubscription (what an old publisher
meets now), advanced publisher (cache, heartbeat, detection) -> RecoveringSubscription (what
fusion-publish and the service do now). Prints median and spread of each and the ratios of
medians to the baseline.
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time
from typing import Any

from fusion import messages as m
from fusion.io.zenoh_advanced import (
    RecoveringSubscription,
    declare_recoverable_publisher,
    wait_for_recovering_subscriber,
)
from fusion.io.zenoh_bus import free_tcp_port, session_config, wait_for_match

KEY = "fusion/bench/meas/cam1"


class _Count:
    def __init__(self, n: int) -> None:
        self.n, self.want, self.done = 0, n, threading.Event()

    def __call__(self, _sample: Any) -> None:
        self.n += 1
        if self.n >= self.want:
            self.done.set()


def _once(hub: Any, cli: Any, way: str, n: int, payload: bytes) -> float:
    """Samples per second one way (see the module docstring)."""
    import zenoh

    count = _Count(n)
    key = f"{KEY}{way}"  # a fresh key per run: no cache or history carried over
    sub = (hub.declare_subscriber(key, count) if way == "plain" else RecoveringSubscription(hub, key, count))
    if way == "advanced":
        pub = declare_recoverable_publisher(cli, key, cache_samples=1000)
        assert wait_for_recovering_subscriber(cli, key, timeout_s=10.0)
    else:
        pub = cli.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        assert wait_for_match(pub, timeout_s=10.0)
    try:
        t0 = time.perf_counter()
        for _ in range(n):
            pub.put(payload)
        assert count.done.wait(60.0), f"{way}: {count.n} of {n} arrived"
        return n / (time.perf_counter() - t0)
    finally:
        pub.undeclare()
        sub.undeclare()


def main(argv: list[str] | None = None) -> int:
    import zenoh

    p = argparse.ArgumentParser(prog="python -m bench.advanced_pubsub")
    p.add_argument("-n", type=int, default=20_000, help="samples per run (default 20000)")
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)
    payload = m.encode(m.Measurement(sensor_id="cam1", t_ns=1_700_000_000_000_000_000, seq=123_456, epoch=1,
                                     data=m.Cartesian(pos_m=[1234.5, -987.6], std_m=[3.0, 3.0])))
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    ways = {"plain": "plain", "plain-to-recovering": "recovering", "advanced": "advanced"}  # name -> _once way
    rates: dict[str, list[float]] = {w: [] for w in ways}
    with zenoh.open(session_config(mode="peer", listen=[endpoint])) as hub, \
            zenoh.open(session_config(mode="client", connect=[endpoint])) as cli:
        _once(hub, cli, "plain", 2000, payload)  # warm-up
        for r in range(args.repeats):
            for w, way in ways.items():
                rates[w].append(_once(hub, cli, way, args.n, payload))
            print(f"repeat {r + 1}: " + ", ".join(f"{w} {rates[w][-1]:,.0f}/s" for w in ways), flush=True)
    base = statistics.median(rates["plain"])
    print(f"\n{args.n} samples of {len(payload)} bytes per run, {args.repeats} repeats")
    for w in ways:
        med = statistics.median(rates[w])
        print(f"  {w:22s} median {med:10,.0f}/s  (min {min(rates[w]):,.0f}, max {max(rates[w]):,.0f})  "
              f"ratio to plain {med / base:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
