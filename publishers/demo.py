"""`fusion demo`: the service and the publishers of a scenario over real Zenoh on loopback,
accelerated, for a bounded time; then a summary of what happened and of the recording written.

Nothing else needs to run: the service is an embedded peer listening on a free 127.0.0.1 port
(multicast scouting off); the publisher is a client of it. The stream is built before the
service opens, so nothing is written when the scenario cannot be built. Setting `stop` (the
CLI does on Ctrl-C) ends publishing early; the service then finishes what it received and
closes its files, and the result says it was interrupted.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from fusion.config import ZenohConfig
from fusion.errors import FusionError
from fusion.io.inspect import Summary, summarise
from fusion.io.zenoh_bus import free_tcp_port, session_config
from fusion.service import Service
from publishers.publish import boot_epoch, publish, sent_words
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream

Progress = Callable[[int, int], None]  # (measurements processed by the service, measurements to send)


def default_out(scenario: str) -> Path:
    """recordings/<scenario>.rrd (the raw input goes beside it, as .fstream)."""
    return Path("recordings") / f"{scenario}.rrd"


@dataclass
class DemoResult:
    recording: Path
    stream: Path
    published: dict[str, int]  # samples put on Zenoh, by kind ("meas", "input", "truth")
    estimates_published: int
    summary: Summary
    wall_s: float
    scenario: str = "mix"
    planned: dict[str, int] = field(default_factory=dict)  # samples the scenario's stream holds, by kind
    counts: dict[str, Any] = field(default_factory=dict)  # the service's counts at the end (status_dict)
    scenario_s: float | None = None  # scenario time streamed (None: the scenario's own length)
    speed: float = 10.0
    interrupted: bool = False


def _open_service(cfg: Any, out: Path, stream: Path) -> tuple[Service, str]:
    """A service on a free loopback port (another port if one is taken between probe and bind)."""
    for attempt in range(5):
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        svc = Service(msgspec.structs.replace(cfg, zenoh=ZenohConfig(mode="peer", listen=[endpoint])),
                      recording_path=out, stream_path=stream)
        try:
            svc.open()
            return svc, endpoint
        except Exception as e:
            if "in use" not in str(e).lower() or attempt == 4:
                raise
    raise AssertionError("unreachable")


class _Monitor:
    """Asks the service for its status (its queryable) a few times a second and reports progress:
    samples handled (measurements, inputs and truth: the service's `received` less its queue)
    of all the samples the demo publishes."""

    def __init__(self, session: Any, namespace: str, total: int, progress: Progress) -> None:
        from fusion.io.query import query_status

        self._ask = lambda: query_status(session, namespace, timeout_s=1.0)
        self._total, self._progress = total, progress
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="demo-progress", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.wait(0.25):
            try:
                c = self._ask().counts
            except FusionError:  # no answer this time (busy or closing): try again
                continue
            self._progress(c.received - c.queued, self._total)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def _wait_idle(svc: Service, runner: threading.Thread, stop: threading.Event, timeout_s: float) -> None:
    """Until the service has handled everything it received (or stop, or it died, or timeout)."""
    deadline = time.monotonic() + timeout_s
    while not stop.is_set() and runner.is_alive() and time.monotonic() < deadline:
        if svc.wait_idle(timeout_s=0.5):
            return


def run_demo(*, scenario: str = "mix", duration_s: float | None = None, out: str | Path | None = None,
             seed: int | None = None, speed: float = 10.0, stop: threading.Event | None = None,
             progress: Progress | None = None) -> DemoResult:
    """Run the scenario end to end; returns what happened (the files are complete on return).
    duration_s: seconds of scenario time (default: the whole scenario). out: the recording
    (default recordings/<scenario>.rrd); the stream goes beside it."""
    import zenoh

    sf = load_scenario_file(scenario_path(scenario))
    spec = sf.scenario
    if seed is not None:
        spec = msgspec.structs.replace(spec, seed=seed)
    if duration_s is not None:
        spec = msgspec.structs.replace(spec, duration_s=duration_s)
    out = Path(out) if out is not None else default_out(scenario)
    stream = out.with_suffix(".fstream")
    samples, truths = build_stream(spec, namespace=sf.service.namespace, epoch=boot_epoch())
    if duration_s is None:
        duration_s = max(int(t.t_ns[-1]) for t in truths if t.t_ns.size) / 1e9
    planned = Counter(s.key.split("/")[2] for s in samples)
    stop = stop if stop is not None else threading.Event()
    if stop.is_set():  # stopped while the stream was being built: nothing has been written
        raise KeyboardInterrupt
    svc, endpoint = _open_service(sf.service, out, stream)
    failed: list[BaseException] = []

    def serve() -> None:
        try:
            svc.run()
        except BaseException as e:
            failed.append(e)

    runner = threading.Thread(target=serve, name="fusion-service")
    t0 = time.monotonic()
    runner.start()
    counts: Counter[str] = Counter()
    try:
        with zenoh.open(session_config(mode="client", connect=[endpoint])) as session:
            monitor = _Monitor(session, svc.ns, sum(planned.values()), progress) if progress is not None else None
            try:
                counts = publish(session, samples, speed=speed, match_timeout_s=10.0, stop=stop)
                _wait_idle(svc, runner, stop, timeout_s=600.0)
            finally:
                if monitor is not None:
                    monitor.close()
    finally:
        svc.stop()
        runner.join()
    if failed:
        raise failed[0]
    wall = time.monotonic() - t0
    return DemoResult(out, stream, dict(counts), svc.published, summarise(out), wall, scenario=scenario,
                      planned=dict(planned), counts=svc.status_dict()["counts"], scenario_s=duration_s, speed=speed,
                      interrupted=stop.is_set())


def _recording_lines(s: Summary) -> list[str]:
    """The few facts of the recording's summary the demo report shows (the rest: fusion inspect)."""
    rmse = "" if s.position_rmse is None else f"; position RMSE against truth {s.position_rmse:.2f} m"
    verdicts = ", ".join(f"{name} {c.mean:.2f} ({c.verdict})" for name, c in (("NIS", s.nis), ("NEES", s.nees))
                         if c.mean is not None)
    lines = [f"  tracks     {len(s.tracks)} confirmed, {s.tentative_only} never confirmed{rmse}"]
    if verdicts:
        lines.append(f"  filters    {verdicts} (mean over all confirmed tracks; NEES over position and velocity; "
                     "95 % chi-square interval widened for time correlation: fusion inspect says how)")
    return lines


def demo_report(r: DemoResult) -> str:
    from fusion.cli.report import counts_line, duration, size

    how = "as fast as possible" if r.speed == 0 else f"at {r.speed:g}x real time"
    span = "the whole scenario" if r.scenario_s is None else f"{r.scenario_s:g} s of scenario time"
    head = (f"demo {r.scenario}: interrupted after {duration(r.wall_s)}; so far:" if r.interrupted
            else f"demo {r.scenario}: {span} {how}, in {duration(r.wall_s)}")
    always = ("meas", "truth")  # said even when none were sent
    sent = (f"  sent       {sent_words(r.published, always=always)}"
            + (f" (of {sent_words(r.planned, always=always)} planned)" if r.interrupted else ""))
    files = [p for p in (r.recording, r.stream) if p.exists()]
    lines = [head, sent]
    if r.counts:
        lines.append(f"  service    {counts_line(r.counts)}")
    lines += _recording_lines(r.summary)
    lines.append("  wrote      " + ", ".join(f"{p} ({size(p.stat().st_size)})" for p in files))
    nxt = [(f"rerun {r.recording}", "look at it"),
           (f"fusion inspect {r.recording}", "the full summary, track by track"),
           (f"fusion replay {r.stream}", "the same input through the tracker again")]
    w = max(len(c) for c, _ in nxt)
    lines += ["next:", *(f"  {c.ljust(w)}   # {why}" for c, why in nxt)]
    return "\n".join(lines)
