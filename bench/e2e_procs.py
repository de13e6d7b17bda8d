"""Processes of the end-to-end benchmark, seen from the benchmark: a real `fusion serve`, the
publisher (bench.e2e_load.publisher_main) and the baseline's counting subscriber.

Everything listens and connects on 127.0.0.1 only. Every process is ended on the way out
(process groups for the service, terminate/kill for the helpers), and every wait has a deadline.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from bench import e2e_load
from fusion import messages as m

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "service.toml"
NS = "demo"
_ctx = mp.get_context("spawn")  # never fork a process that holds zenoh threads


def free_endpoint() -> str:
    from fusion.io.zenoh_bus import free_tcp_port

    return f"tcp/127.0.0.1:{free_tcp_port()}"


def service_config(folder: Path, *, recording: bool, recording_keys: dict[str, Any] | None = None) -> Path:
    """configs/service.toml as shipped, or a copy with [recording] enabled = false, or with the
    given [recording] keys set (an A/B of one setting: bench.recording_ab)."""
    keys = dict(recording_keys or {}) | ({} if recording else {"enabled": False})
    if not keys:
        return CONFIG
    text = CONFIG.read_text()
    section = text.split("\n[recording]\n")[1].split("\n[")[0] if "\n[recording]\n" in text else None
    assert section is not None and not any(f"\n{k} " in "\n" + section for k in keys), "unexpected service.toml"
    lines = "".join(f"{k} = {str(v).lower() if isinstance(v, bool) else repr(v)}\n" for k, v in sorted(keys.items()))
    path = folder / "service-variant.toml"
    path.write_text(text.replace("\n[recording]\n", "\n[recording]\n" + lines))
    return path


class ServiceProcess:
    """`fusion serve --config CONFIG --listen tcp/127.0.0.1:PORT --recordings FOLDER` in its own
    process group, and a client session of the benchmark's own (status queries, a subscriber
    of the estimates that calls `on_estimate(receive_ns, payload)`)."""

    def __init__(self, folder: Path, *, recording: bool, on_estimate: Any = None,
                 start_timeout_s: float = 60.0, recording_keys: dict[str, Any] | None = None) -> None:
        self.folder = folder
        self.recording = recording
        self.recording_keys = recording_keys
        self.on_estimate = on_estimate
        self.start_timeout_s = start_timeout_s
        self.proc: subprocess.Popen[bytes] | None = None
        self.session: Any = None
        self.endpoint = ""

    def __enter__(self) -> ServiceProcess:
        try:
            for _attempt in range(3):  # the port may be taken between the probe and the bind
                if self._start():
                    return self
                self._kill()
            raise RuntimeError(f"fusion serve did not start: {self.log_tail()}")
        except BaseException:
            self.__exit__(None, None, None)
            raise

    def _start(self) -> bool:
        import zenoh

        from fusion.io.zenoh_bus import session_config

        self.endpoint = free_endpoint()
        rec = self.folder / "recordings"
        rec.mkdir(exist_ok=True)
        config = service_config(self.folder, recording=self.recording, recording_keys=self.recording_keys)
        cmd = [sys.executable, "-m", "fusion", "serve", "--config", str(config), "--listen", self.endpoint,
               "--recordings", str(rec)]
        self._log = open(self.folder / "serve.log", "ab")  # noqa: SIM115 (closed in _kill)
        self.proc = subprocess.Popen(cmd, cwd=self.folder, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                return False
            if self.session is None:
                try:
                    self.session = zenoh.open(session_config(mode="client", connect=[self.endpoint]))
                except Exception:  # not listening yet
                    time.sleep(0.2)
                    continue
            if self.status() is not None:
                if self.on_estimate is not None:
                    self._sub = self.session.declare_subscriber(m.all_tracks_key(NS), self._on_sample)
                return True
            time.sleep(0.1)
        return False

    def _on_sample(self, sample: Any) -> None:
        self.on_estimate(time.time_ns(), sample.payload.to_bytes())

    def status(self, timeout_s: float = 2.0) -> m.ServiceStatus | None:
        for r in self.session.get(m.status_key(NS), timeout=timeout_s):
            if r.ok is not None:
                return m.decode_status(r.ok.payload.to_bytes())
        return None

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def rss_kb(self) -> int:
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        raise RuntimeError("no VmRSS")

    def folder_bytes(self) -> dict[str, int]:
        """Bytes on disk in the recordings folder, by suffix (.rrd, .fstream)."""
        out: dict[str, int] = {}
        for p in (self.folder / "recordings").iterdir():
            out[p.suffix] = out.get(p.suffix, 0) + p.stat().st_size
        return out

    def log_tail(self, n: int = 800) -> str:
        try:
            return (self.folder / "serve.log").read_bytes()[-n:].decode(errors="replace")
        except OSError:
            return ""

    def _kill(self) -> None:
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.proc is not None and self.proc.poll() is None:
            # SIGTERM makes the service drain its queue first (minutes when it is far behind): 3 s, then SIGKILL
            os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(3.0)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(10.0)
        if getattr(self, "_log", None) is not None:
            self._log.close()
            self._log = None

    def __exit__(self, *exc: object) -> None:
        self._kill()


def prime(svc: ServiceProcess, pub: Publisher, *, timeout_s: float) -> tuple[float, m.Counts]:
    """Send the primer (a few scans of 3 far-away targets, sensor times = now) and wait until the
    service has handled it: imports, compiled kernels and the recording are loaded before any
    timing. Returns the seconds it took and the counts then."""
    t = time.monotonic()
    received0 = svc.status().counts.received  # type: ignore[union-attr]
    sent = pub.call("prime")["sent"]
    while time.monotonic() < t + timeout_s:
        st = svc.status()
        if st is not None and st.counts.received >= received0 + sent and st.counts.queued == 0:
            return time.monotonic() - t, st.counts
        time.sleep(0.1)
    raise TimeoutError(f"the service did not handle the primer within {timeout_s:.0f} s")


class Publisher:
    """The publisher process (bench.e2e_load.publisher_main): `call(cmd, arg)` waits for the
    reply (deadline), `send` + `result` split it so the caller can poll meanwhile."""

    def __init__(self) -> None:
        self.conn, child = _ctx.Pipe()
        self.proc = _ctx.Process(target=e2e_load.publisher_main, args=(child, NS), daemon=True)

    def __enter__(self) -> Publisher:
        self.proc.start()
        return self

    def send(self, cmd: str, arg: Any = None) -> None:
        self.conn.send((cmd, arg))

    def result(self, timeout_s: float) -> Any:
        if not self.conn.poll(timeout_s):
            raise TimeoutError(f"the publisher did not answer within {timeout_s:.0f} s")
        status, value = self.conn.recv()
        if status != "ok":
            raise RuntimeError(f"publisher: {value}")
        return value

    def call(self, cmd: str, arg: Any = None, timeout_s: float = 60.0) -> Any:
        self.send(cmd, arg)
        return self.result(timeout_s)

    def __exit__(self, *exc: object) -> None:
        try:
            if self.proc.is_alive():
                self.conn.send(("quit", None))
                self.proc.join(5.0)
        except OSError:
            pass
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5.0)


def zenoh_baseline(pub: Publisher, expect: int, *, timeout_s: float = 60.0) -> dict[str, float]:
    """The prepared messages from the publisher to a counting subscriber in its own process (a
    peer listening on 127.0.0.1, like the service): messages/s between the first and last arrival."""
    q = _ctx.Queue()
    for _attempt in range(3):
        endpoint = free_endpoint()
        proc = _ctx.Process(target=e2e_load.counter_main, args=(endpoint, m.all_meas_key(NS), expect, timeout_s, q),
                            daemon=True)
        proc.start()
        try:
            msg = q.get(timeout=60.0)
            if msg[0] == "error":
                continue
            pub.call("connect", endpoint)
            sent = pub.call("blast", timeout_s=timeout_s)
            _, count, first_ns, last_ns = q.get(timeout=timeout_s + 10.0)
            pub.call("disconnect")
            return {"received": count, "sent": sent["sent"], "rate": (count - 1) / max(last_ns - first_ns, 1) * 1e9,
                    "send_rate": sent["sent"] / max(sent["t1_ns"] - sent["t0_ns"], 1) * 1e9}
        finally:
            if proc.is_alive():
                proc.join(5.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)
    raise RuntimeError("the baseline subscriber could not listen on a free port")
