"""`fusion demo`: the service and the publishers of a scenario over real Zenoh on loopback,
accelerated, for a bounded time; then a summary of the recording it wrote.

Nothing else needs to run: the service is an embedded peer listening on a free 127.0.0.1 port
(multicast scouting off); the publisher is a client of it.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

import msgspec

from fusion.config import ZenohConfig
from fusion.io.inspect import Summary, format_summary, summarise
from fusion.io.zenoh_bus import free_tcp_port, session_config
from fusion.service import Service
from publishers.publish import publish
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream


@dataclass
class DemoResult:
    recording: Path
    stream: Path
    published: dict[str, int]
    estimates_published: int
    summary: Summary
    wall_s: float


def run_demo(*, scenario: str = "mix", duration_s: float | None = 30.0, out: str | Path = "recordings/demo.rrd",
             seed: int | None = None, speed: float = 10.0) -> DemoResult:
    """Run the scenario end to end; returns what happened (the recording is complete on return)."""
    import zenoh

    sf = load_scenario_file(scenario_path(scenario))
    spec = sf.scenario
    if seed is not None:
        spec = msgspec.structs.replace(spec, seed=seed)
    if duration_s is not None:
        spec = msgspec.structs.replace(spec, duration_s=duration_s)
    out = Path(out)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    cfg = msgspec.structs.replace(sf.service, zenoh=ZenohConfig(mode="peer", listen=[endpoint]))
    stream = out.with_suffix(".fstream")
    svc = Service(cfg, recording_path=out, stream_path=stream)
    svc.open()
    runner = threading.Thread(target=svc.run, name="fusion-service")
    t0 = time.monotonic()
    runner.start()
    try:
        samples, _ = build_stream(spec, namespace=cfg.namespace)
        with zenoh.open(session_config(mode="client", connect=[endpoint])) as session:
            counts = publish(session, samples, speed=speed, match_timeout_s=10.0)
        svc.wait_idle(timeout_s=120.0)
    finally:
        svc.stop()
        runner.join()
    wall = time.monotonic() - t0
    return DemoResult(out, stream, dict(counts), svc.published, summarise(out), wall)


def demo_report(r: DemoResult) -> str:
    s = r.summary
    c = s.counts
    lines = [
        f"demo finished in {r.wall_s:.1f} s: published {r.published.get('meas', 0)} measurements and "
        f"{r.published.get('truth', 0)} truth samples; the service published {r.estimates_published} estimates",
        f"late measurements folded in by replay: {c.get('late_applied', 0)} ({c.get('replays', 0)} replays); "
        f"duplicates: {c.get('refused/duplicate', 0)}; refused otherwise: "
        + (", ".join(f"{k[len('refused/'):]}={v}" for k, v in c.items()
                     if k.startswith("refused/") and k != "refused/duplicate" and v) or "none"),
        "",
        format_summary(s),
        "",
        f"open it in the Rerun viewer:  rerun {r.recording}",
        f"replay the recorded input:    fusion replay {r.stream} --out {r.recording.with_name('replay.rrd')}",
    ]
    return "\n".join(lines)
