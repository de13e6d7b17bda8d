"""SIGKILL of a real `fusion serve` at seeded-random moments (issue #13, "Crash"): after each
kill every .rrd in the folder reads up to where it was cut (and `fusion inspect` says so without
a traceback), every .fstream reads up to its last complete frame and holds a prefix of what was
sent on each key, and the checkpoint is a complete one or absent, never torn; a service
restarted on the same folder resumes it (status: tracks and age) and tracks again."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from fusion import messages as m
from fusion.config import load_service_config
from fusion.io.checkpoint import MAGIC, read_checkpoint
from fusion.io.rrd_read import read_chunks
from fusion.io.streamfile import StreamReader
from fusion.io.zenoh_bus import free_tcp_port
from publishers.publish import publish
from publishers.stream import Sample, build_stream
from tests.cli.helpers import SERVICE_TOML, run, start
from tests.service.harness import client, query, scenario_config

INTERVAL_S = 1.0  # checkpoint interval of the service under test


def _config(tmp: Path, interval_s: float = INTERVAL_S, name: str = "service.toml") -> Path:
    """configs/service.toml with checkpoints every interval_s and recordings flushed every 0.2 s."""
    text = SERVICE_TOML.read_text()
    assert text.rstrip().endswith('prefix = "fusion"'), "[recording] is no longer the last section"
    p = tmp / name
    p.write_text(text.rstrip() + f"\nflush_interval_s = 0.2\n\n[checkpoint]\ninterval_s = {interval_s}\n")
    return p


def _shifted(samples: list[Sample], dt_ns: int) -> list[Sample]:
    """The samples with sensor, truth and arrival times moved dt_ns later (the sensors' clocks ran on)."""
    out = []
    for x in samples:
        msg = m.decode_any(x.payload)
        out.append(Sample(x.arrival_ns + dt_ns, x.key, m.encode(msgspec.structs.replace(msg, t_ns=msg.t_ns + dt_ns))))
    return out


class Served:
    """One `fusion serve` process on `rec`, with a client session on its loopback endpoint."""

    def __init__(self, cfg: Path, rec: Path, cwd: Path) -> None:
        self.ep = f"tcp/127.0.0.1:{free_tcp_port()}"
        self.proc = start("fusion", "serve", "-c", str(cfg), "-l", self.ep, "--recordings", str(rec), cwd=cwd)
        try:
            line = self.proc.stdout.readline()  # type: ignore[union-attr]
            assert line.startswith("fusion serving namespace 'demo'"), (line, self._err())
            self.session = client(self.ep)
        except BaseException:
            self.proc.kill()
            self.proc.wait(timeout=10)
            raise
        self.pub_thread: threading.Thread | None = None
        self.stop_pub = threading.Event()

    def _err(self) -> str:
        if self.proc.poll() is None:
            return ""
        return self.proc.stderr.read()  # type: ignore[union-attr]

    def status(self) -> m.ServiceStatus:
        return m.decode_status(query(self.session, m.status_key("demo")))

    def publish_in_background(self, samples: list[Sample]) -> None:
        def go() -> None:
            with contextlib.suppress(Exception):
                publish(self.session, samples, speed=1.0, match_timeout_s=5.0, stop=self.stop_pub)

        self.pub_thread = threading.Thread(target=go, name="crash-publisher")
        self.pub_thread.start()

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        assert self.proc.returncode == -signal.SIGKILL
        self.close()

    def close(self) -> None:
        self.stop_pub.set()
        if self.pub_thread is not None:
            self.pub_thread.join(timeout=20)
            assert not self.pub_thread.is_alive()
        self.session.close()
        for f in (self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()


def _wait(pred: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def _check_after_kill(rec: Path, cwd: Path, cfg_path: Path, sent: list[list[Sample]], last: m.ServiceStatus, *,
                      checkpoint: str) -> None:
    """(a) the recordings, (b) the streams (the i-th oldest holds run i's samples; `last`: the
    killed service's last status), (c) the checkpoint. The frames are compared with what was sent
    as a set: zenoh's sample recovery may deliver a missed sample after later ones."""
    rrds = sorted(rec.glob("*.rrd"))
    assert len(rrds) == len(sent), rrds
    for p in rrds:
        chunks, dropped = read_chunks(p)
        assert dropped <= p.stat().st_size
        r = run("fusion", "inspect", str(p), cwd=cwd)
        assert "Traceback" not in r.stderr, r.stderr
        if r.returncode != 0:
            assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert chunks, f"{rrds[-1]}: nothing readable although it was flushed"
    streams = sorted(rec.glob("*.fstream"))
    assert len(streams) == len(sent), streams
    for p, samples in zip(streams, sent, strict=True):
        sent_set = {(s.key, s.payload) for s in samples}
        frames = [(key, payload) for _, key, payload in StreamReader(p)]
        assert all(f in sent_set for f in frames), f"{p}: a frame that was not sent"
    # nothing the killed service had handled (the status it gave last) is missing from its stream
    c = last.counts
    assert len(frames) >= c.applied + c.truth + c.duplicates, (len(frames), c)
    cp = rec / "fusion.checkpoint"
    tracker = load_service_config(cfg_path).tracker
    if checkpoint == "absent":
        assert not cp.exists()
    else:
        r = read_checkpoint(cp, tracker)  # CheckpointError on a torn file
        assert r is not None, "no checkpoint although the service wrote one"
        if checkpoint == "tracks":
            assert r.tracks > 0


def _feed_then_kill(sv: Served, batch: list[Sample], sent: list[list[Sample]], *, writes: int,
                    then_s: float) -> m.ServiceStatus:
    """Publish `batch` (kept in `sent`) in real time, wait for `writes` checkpoint writes and
    then_s more, then SIGKILL the service: its last status before the kill."""
    sent.append(batch)
    try:
        sv.publish_in_background(batch)
        _wait(lambda: sv.status().checkpoint.written >= writes, 15.0,  # type: ignore[union-attr]
              f"{writes} checkpoint writes")
        time.sleep(then_s)
        return sv.status()
    finally:
        sv.kill()


def _assert_resumed(sv: Served) -> m.ServiceStatus:
    """The restarted service's status says it resumed tracks from a checkpoint written seconds ago."""
    st = sv.status()
    assert st.checkpoint is not None and st.checkpoint.resumed_tracks > 0, st.checkpoint
    assert st.checkpoint.resumed_age_s is not None and 0.0 < st.checkpoint.resumed_age_s < 30.0
    assert st.checkpoint.refused is None
    return st


def test_sigkill_at_random_moments_leaves_readable_files_and_a_whole_checkpoint(tmp_path: Path) -> None:
    rng = np.random.default_rng(13)
    cfg_path = _config(tmp_path)
    rec = tmp_path / "rec"
    spec, _ = scenario_config("mix")
    samples, _ = build_stream(msgspec.structs.replace(spec, duration_s=12.0), namespace="demo")
    t0 = time.monotonic_ns()

    def part(a_s: float, b_s: float) -> list[Sample]:
        """The samples arriving in [a_s, b_s) of the scenario, moved to now on the sensors' clock."""
        chosen = [s for s in samples if a_s * 1e9 <= s.arrival_ns < b_s * 1e9]
        return _shifted(chosen, time.monotonic_ns() - t0)

    sent: list[list[Sample]] = []
    # 1: killed before the first checkpoint write, while samples arrive (a service whose first
    # write is due a minute after its start: on a loaded machine, start-up and the feed can take
    # longer than INTERVAL_S, and the write this phase must come before would happen first)
    sv = Served(_config(tmp_path, 60.0, "service-first.toml"), rec, tmp_path)
    last = _feed_then_kill(sv, part(0.0, 4.0), sent, writes=0, then_s=rng.uniform(0.1, 0.4))
    assert last.checkpoint is not None and last.checkpoint.written == 0
    _check_after_kill(rec, tmp_path, cfg_path, sent, last, checkpoint="absent")
    # what a kill between the temporary file's write and its rename leaves: the next start removes it
    torn = rec / ".fusion.checkpoint.99999.tmp"
    torn.write_bytes(MAGIC + b"\x82\xafwritten_wall_ns")

    # 2: a restart finds no checkpoint; killed mid-stream, between checkpoint writes
    sv = Served(cfg_path, rec, tmp_path)
    st = sv.status()
    assert st.checkpoint is not None and st.checkpoint.resumed_tracks == 0 and st.checkpoint.refused is None
    assert not torn.exists() and not (rec / "fusion.checkpoint").exists()
    last = _feed_then_kill(sv, part(0.0, 8.0), sent, writes=2, then_s=rng.uniform(0.2, 0.8) * INTERVAL_S)
    _check_after_kill(rec, tmp_path, cfg_path, sent, last, checkpoint="tracks")

    # 3: resumed; killed right after a checkpoint interval (while the write may be under way)
    sv = Served(cfg_path, rec, tmp_path)
    _assert_resumed(sv)
    last = _feed_then_kill(sv, part(8.0, 12.0), sent, writes=1, then_s=INTERVAL_S + rng.uniform(0.0, 0.03))
    _check_after_kill(rec, tmp_path, cfg_path, sent, last, checkpoint="tracks")

    # 4: resumed once more, it tracks again and stops cleanly
    sv = Served(cfg_path, rec, tmp_path)
    try:
        before = _assert_resumed(sv).counts.applied
        publish(sv.session, part(8.0, 10.0), speed=4.0, match_timeout_s=5.0)
        _wait(lambda: sv.status().counts.applied > before and sv.status().tracks.get("confirmed", 0) > 0,
              15.0, "tracking after the restart")
        sv.proc.send_signal(signal.SIGINT)
        _, err = sv.proc.communicate(timeout=60)
    finally:
        if sv.proc.poll() is None:
            sv.proc.kill()
        sv.close()
    assert sv.proc.returncode == 0, err
    assert "Traceback" not in err
    assert not list(rec.glob(".fusion.checkpoint.*.tmp")), "a temporary checkpoint file was left behind"
    assert read_checkpoint(rec / "fusion.checkpoint", load_service_config(cfg_path).tracker) is not None
