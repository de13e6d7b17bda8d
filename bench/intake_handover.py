"""How a loop's samples reach it from Zenoh: a callback per sample against the service's
channel threads (fusion.io.channel_intake), `python -m bench --only handover`.

A loop stands in for the service's: it takes the samples a producer queued (a deque and an
Event, as the intake queue and the service's wake event) and does `work_us` of Python per sample
(a fixed count of bytecode-level additions, calibrated once per run in the parent and passed on,
so every child does the same work). A publisher process (a Zenoh client on 127.0.0.1,
congestion control BLOCK) blasts `n` samples of 147 bytes at the loop's process (a peer
listening on 127.0.0.1, scouting off). Figures: samples/s from the loop's first to its last
sample, and the loop thread's CPU per sample. The two ways run in fresh processes, interleaved,
`pairs` times:
  callback  a callback subscriber queueing each sample (what the service did before);
  channel   a FIFO channel of 4096 and ChannelIntake's thread, queueing chunks of samples.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import statistics
import sys
import time
from collections import deque
from typing import Any

_ctx = mp.get_context("spawn")
KEY = "bench/handover/meas"


def _config(mode: str, endpoint: str) -> Any:
    from fusion.io.zenoh_bus import session_config

    return session_config(mode=mode, listen=[endpoint]) if mode == "peer" else \
        session_config(mode=mode, connect=[endpoint])


def _publisher(endpoint: str, n: int, ready: Any, go: Any) -> None:
    import zenoh

    with zenoh.open(_config("client", endpoint)) as s:
        p = s.declare_publisher(KEY, congestion_control=zenoh.CongestionControl.BLOCK)
        deadline = time.monotonic() + 10.0
        while not p.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.01)
        ready.put("ready")
        go.get(timeout=30.0)
        payload = bytes(147)
        for _ in range(n):
            p.put(payload)
        go.get(timeout=60.0)  # stay connected until the loop has everything


def _work(iterations: int) -> int:
    x = 0
    for i in range(iterations):
        x += i
    return x


def calibrate(work_us: float) -> int:
    """Iterations of _work that take work_us of this thread's CPU (median of 5)."""
    probe = 200_000
    took = []
    for _ in range(5):
        t0 = time.thread_time_ns()
        _work(probe)
        took.append(time.thread_time_ns() - t0)
    return max(1, round(probe * work_us * 1e3 / statistics.median(took)))


def _loop(way: str, n: int, iterations: int, out: Any) -> None:
    import threading

    import zenoh

    from fusion.io.channel_intake import ChannelIntake
    from fusion.io.zenoh_bus import free_tcp_port

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    got: deque[tuple[int, str, bytes]] = deque()
    wake = threading.Event()
    with zenoh.open(_config("peer", endpoint)) as s:
        intake = None
        if way == "callback":
            def on(sample: Any) -> None:
                got.append((time.time_ns(), str(sample.key_expr), sample.payload.to_bytes()))
                if not wake.is_set():
                    wake.set()
            sub = s.declare_subscriber(KEY, on)
        else:
            sub = s.declare_subscriber(KEY, zenoh.handlers.FifoChannel(4096))

            def take(taken: list[tuple[int, Any]]) -> None:
                for a, sample in taken:
                    got.append((a, str(sample.key_expr), sample.payload.to_bytes()))
                if not wake.is_set():
                    wake.set()
            intake = ChannelIntake([sub.handler], take)
        ready, go = _ctx.Queue(), _ctx.Queue()
        pub = _ctx.Process(target=_publisher, args=(endpoint, n, ready, go), daemon=True)
        pub.start()
        try:
            ready.get(timeout=60.0)
            go.put("go")
            done, t0, c0 = 0, None, time.thread_time_ns()
            pop = got.popleft
            while done < n:
                if not got:
                    wake.wait(0.05)
                    wake.clear()
                    continue
                if t0 is None:
                    t0 = time.perf_counter()
                while got:
                    pop()
                    _work(iterations)
                    done += 1
            t1, c1 = time.perf_counter(), time.thread_time_ns()
            go.put("bye")
        finally:
            pub.join(10.0)
            if pub.is_alive():
                pub.kill()
            sub.undeclare()
            if intake is not None:
                intake.join()
    out.put({"rate": (n - 1) / (t1 - (t0 or t1) or 1e-9), "loop_cpu_us": (c1 - c0) / n / 1e3})


def _one(way: str, n: int, iterations: int) -> dict[str, float]:
    out = _ctx.Queue()
    p = _ctx.Process(target=_loop, args=(way, n, iterations, out))
    p.start()
    try:
        return out.get(timeout=180.0)
    finally:
        p.join(10.0)
        if p.is_alive():
            p.kill()


def run(*, pairs: int = 3, quick: bool = False, work_us: float = 16.0) -> dict[str, Any]:
    n = 40_000 if quick else 120_000
    iterations = calibrate(work_us)
    ways = ("callback", "channel")
    res: dict[str, list[dict[str, float]]] = {w: [] for w in ways}
    print(f"intake hand-over: {n} samples blasted at a loop doing ~{work_us:g} us of Python each "
          f"({iterations} additions), {pairs} interleaved pairs")
    for k in range(pairs):
        for w in (ways if k % 2 == 0 else ways[::-1]):
            r = _one(w, n, iterations)
            res[w].append(r)
            print(f"  pair {k} {w:8s}: {r['rate']:9.0f} samples/s, loop {r['loop_cpu_us']:.2f} us CPU/sample",
                  flush=True)
    ratio = [c["rate"] / b["rate"] for c, b in zip(res["channel"], res["callback"], strict=True)]
    summary = {w: {"rate_median": statistics.median(r["rate"] for r in res[w]),
                   "rate_min": min(r["rate"] for r in res[w]), "rate_max": max(r["rate"] for r in res[w]),
                   "loop_cpu_us_median": statistics.median(r["loop_cpu_us"] for r in res[w])} for w in ways}
    print("| way | samples/s, median (min-max) | loop CPU per sample |")
    print("|---|---|---|")
    for w in ways:
        s = summary[w]
        print(f"| {w} | {s['rate_median']:.0f} ({s['rate_min']:.0f}-{s['rate_max']:.0f}) | "
              f"{s['loop_cpu_us_median']:.2f} us |")
    print("channel/callback per pair:", ", ".join(f"{r:.2f}" for r in ratio))
    return {"n": n, "work_us": work_us, "iterations": iterations, "runs": res, "summary": summary,
            "ratio_per_pair": ratio}


if __name__ == "__main__":
    print(json.dumps(run(pairs=int(sys.argv[1]) if len(sys.argv) > 1 else 3)["summary"]))
