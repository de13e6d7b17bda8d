"""SIGTERM with a full queue: the drain stops at intake.drain_deadline_s, what is left is
dropped and counted ("shutdown") by the kind its key names (truth samples as truth), and the
recording is complete."""

from __future__ import annotations

import ast
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fusion import messages as m
from fusion.cli.report import counts_line
from fusion.io.inspect import summarise
from fusion.io.streamfile import StreamReader
from fusion.io.zenoh_bus import free_tcp_port
from publishers.spec import scenario_path
from tests.service.harness import client, query
from tests.service.reliability_helpers import publisher

ROOT = Path(__file__).resolve().parents[2]
RERUN = Path(__import__("rerun_cli").__file__).parent / "rerun"


def test_sigterm_with_a_full_queue_stops_at_the_deadline_with_a_complete_recording(tmp_path: Path) -> None:
    conf = tmp_path / "serve.toml"
    conf.write_text(scenario_path("mix").read_text()
                    + "\n[service.intake]\nbatch_max = 200\ndrain_deadline_s = 0.5\n")
    port = free_tcp_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "fusion", "serve", "--config", str(conf), "--listen", f"tcp/127.0.0.1:{port}",
         "--recordings", str(tmp_path / "rec")],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, cwd=ROOT,
    )
    try:
        line = ""
        for _ in range(20):
            line = proc.stdout.readline().decode()  # type: ignore[union-attr]
            if "serving" in line or not line:
                break
        assert "serving" in line
        rng = np.random.default_rng(5)
        s = client(f"tcp/127.0.0.1:{port}")
        try:
            p = publisher(s, m.meas_key("demo", "cam1"))
            t0 = time.time_ns()
            n = 40_000  # 200 per scan, scattered: many tentative tracks, slow to process
            for i in range(n):
                xy = rng.uniform(-3000.0, 3000.0, 2).tolist()
                p.put(m.encode(m.Measurement(sensor_id="cam1", t_ns=t0 + (i // 200) * 10_000_000, seq=i,
                                             data=m.Cartesian(pos_m=xy, std_m=[3.0, 3.0]))))
            bad_truth = publisher(s, m.truth_key("demo", "t1"))
            for _ in range(n_truth := 500):  # refused as malformed, or dropped at shutdown: truth either way
                bad_truth.put(b"\x00")
            st = m.decode_status(query(s, m.status_key("demo")))
        finally:
            s.close()
        assert st.queue_depth > 1000, "the queue was not full at SIGTERM: the test shows nothing"
        t_term = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
        stop_s = time.monotonic() - t_term
    finally:
        if proc.poll() is None:
            proc.kill()
    text = out.decode()
    assert proc.returncode == 0, text
    assert "drain deadline of 0.5 s reached" in text
    assert stop_s < 10.0, f"shutdown took {stop_s:.1f} s with a 0.5 s drain deadline"
    rrd = sorted((tmp_path / "rec").glob("*.rrd"))
    assert len(rrd) == 1
    v = subprocess.run([str(RERUN), "rrd", "verify", str(rrd[0])], capture_output=True, text=True, timeout=60)
    assert v.returncode == 0, v.stderr
    summary = summarise(rrd[0])
    assert summary.complete
    c = summary.counts
    assert c["refused/shutdown"] > 0
    frames = sum(1 for _ in StreamReader(rrd[0].with_suffix(".fstream")))
    assert frames + c["refused/shutdown"] == n + n_truth, "a sample was neither processed (in the stream) nor counted"
    stopped = next(x for x in text.splitlines() if "fusion service stopped: " in x)
    final = ast.literal_eval(stopped.split("fusion service stopped: ", 1)[1])
    assert (final["truth"], final["truth_refused"]) == (0, n_truth), final
    assert counts_line(final).startswith(f"received {n} measurements: "), counts_line(final)
