"""The happy paths and their edges through the real console scripts: demo (outputs per
scenario, a summary whose words match its numbers, Ctrl-C), replay and inspect (progress on a
terminal only, a closed pipe), and a served namespace asked by status/tracks, fed by
fusion-publish and recorded by fusion record."""

from __future__ import annotations

import json
import re
import signal
import time
from pathlib import Path

import pytest

from fusion.cli.runner import Exit
from fusion.io.zenoh_bus import free_tcp_port
from tests.cli.helpers import SERVICE_TOML, run, run_on_terminal, start, stop


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str, str]:
    """A short demo of the smallest scenario, run once: (its folder, its stdout, its stderr)."""
    d = tmp_path_factory.mktemp("demo")
    r = run("fusion", "demo", "-s", "cv1d_a", "--duration", "3", "--speed", "max", cwd=d)
    assert r.returncode == 0, r.stderr
    return d, r.stdout, r.stderr


def test_demo_writes_per_scenario_files_and_a_consistent_summary(demo_dir: tuple[Path, str, str]) -> None:
    d, out, _ = demo_dir
    assert (d / "recordings" / "cv1d_a.rrd").exists() and (d / "recordings" / "cv1d_a.fstream").exists()
    assert not (d / "recordings" / "demo.rrd").exists()
    sent = int(re.search(r"sent\s+(\d+) measurements", out).group(1))  # type: ignore[union-attr]
    m = re.search(r"received (\d+) measurements: (\d+) applied, (\d+) duplicates dropped, (\d+) refused", out)
    assert m, out
    received, applied, dup, refused = map(int, m.groups())
    assert received == sent == applied + dup + refused, out
    assert "refused: none" not in out and "refused=" not in out, "one word per number"
    assert "wrote      recordings/cv1d_a.rrd" in out and "recordings/cv1d_a.fstream" in out
    assert "fusion replay recordings/cv1d_a.fstream" in out


def test_demo_ctrl_c_prints_the_summary_so_far(tmp_path: Path) -> None:
    p = start("fusion", "demo", "-s", "mix", "--duration", "30", "--speed", "1", cwd=tmp_path)
    rrd = tmp_path / "recordings" / "mix.rrd"
    deadline = time.monotonic() + 120
    while not rrd.exists() and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.1)
    assert rrd.exists(), "the demo did not start"
    time.sleep(1.5)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=180)
    assert p.returncode == Exit.INTERRUPTED, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert "demo mix: interrupted after" in out and "planned)" in out
    assert "recordings/mix.rrd" in out and "recordings/mix.fstream" in out
    assert err.strip().splitlines()[-1].startswith("fusion demo: interrupted: the summary above")
    with rrd.open("rb") as f:  # closed normally: rerun's footer is there
        f.seek(-64, 2)
        assert b"RRF2FOOT" in f.read()


def test_replay_progress_on_a_terminal_only(demo_dir: tuple[Path, str, str]) -> None:
    """A bar with rate and ETA on a terminal; the summary on stdout; the output beside the stream."""
    d, _, _ = demo_dir
    code, out, term = run_on_terminal("fusion", "replay", "recordings/cv1d_a.fstream", cwd=d)
    assert code == 0, term
    assert re.search(r"replay cv1d_a\.fstream: 100%\|.*\| 60/60 \[\d\d:\d\d<\d\d:\d\d, .*sample/s\]", term), term
    m = re.search(r"replayed 60 samples in .*: received (\d+) measurements: (\d+) applied, (\d+) duplicates "
                  r"dropped, (\d+) refused", out)
    assert m, out
    assert int(m.group(1)) == sum(map(int, m.groups()[1:]))
    assert "wrote recordings/cv1d_a-replay.rrd" in out and (d / "recordings" / "cv1d_a-replay.rrd").exists()


def test_quiet_in_a_pipe(demo_dir: tuple[Path, str, str]) -> None:
    """No bar and no carriage return when stderr is not a terminal (the demo has a bar too)."""
    _, _, err = demo_dir
    assert "\r" not in err and "meas/s" not in err and "simulating" not in err


def test_inspect_into_a_closed_pipe_is_quiet(demo_dir: tuple[Path, str, str]) -> None:
    """`fusion inspect X | head`: the reader goes away before the output; exit 141, no traceback."""
    d, _, _ = demo_dir
    p = start("fusion", "inspect", "recordings/cv1d_a.rrd", "--json", cwd=d)
    p.stdout.close()  # type: ignore[union-attr]
    err = p.stderr.read()  # type: ignore[union-attr]
    assert p.wait(timeout=120) == Exit.BROKEN_PIPE, err
    assert err == ""


def test_serve_status_tracks_publish_record(tmp_path: Path) -> None:
    """A served namespace on a free loopback port: fusion-publish feeds it, fusion record keeps the
    samples, status and tracks read its queryables; Ctrl-C ends the service with a summary."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    svc = start("fusion", "serve", "-c", str(SERVICE_TOML), "-l", ep, "--recordings", "rec", cwd=tmp_path)
    rec = None
    try:
        line = svc.stdout.readline()  # type: ignore[union-attr]
        assert line.startswith(f"fusion serving namespace 'demo' (listening on {ep}); recording to rec/"), line
        rec = start("fusion", "record", "-e", ep, "-o", "in.fstream", "--duration", "60", cwd=tmp_path)
        assert rec.stdout.readline().startswith("recording fusion/demo/meas/*")  # type: ignore[union-attr]
        time.sleep(0.5)
        pub = run("fusion-publish", "-s", "mix", "--duration", "4", "--speed", "max", "-e", ep, cwd=tmp_path)
        assert pub.returncode == 0, pub.stderr
        m = re.match(r"published (\d+) measurements and (\d+) truth samples on fusion/demo/", pub.stdout)
        assert m, pub.stdout
        n_meas, n_truth = int(m.group(1)), int(m.group(2))
        deadline = time.monotonic() + 90
        while True:  # the service's answer is refreshed by its loop: wait until it has caught up
            st = json.loads(run("fusion", "status", "-e", ep, "--json", cwd=tmp_path).stdout)
            c = st["counts"]
            if (c["received"] == n_meas + n_truth and not c["queued"]) or time.monotonic() > deadline:
                break
            time.sleep(0.5)
        assert st["type"] == "status" and c["received"] == n_meas + n_truth and c["queued"] == 0, st
        assert c["truth"] == n_truth
        text = run("fusion", "status", "-e", ep, cwd=tmp_path)
        assert text.returncode == 0
        assert re.search(rf"received {n_meas} measurements: \d+ applied", text.stdout), text.stdout
        tr = run("fusion", "tracks", "-e", ep, cwd=tmp_path)
        assert tr.returncode == 0 and "namespace 'demo': " in tr.stdout, tr.stdout
        snap = json.loads(run("fusion", "tracks", "-e", ep, "--json", cwd=tmp_path).stdout)
        assert snap["type"] == "snapshot"
        if snap["estimates"]:  # the tracks live on between the two queries: their number may change
            assert re.search(r"\d+ confirmed tracks \(model imm", tr.stdout), tr.stdout
        rec.send_signal(signal.SIGINT)
        rout, rerr = rec.communicate(timeout=60)
        assert rec.returncode == 0, rerr
        n = int(re.search(r"recorded (\d+) samples to in\.fstream", rout).group(1))  # type: ignore[union-attr]
        assert n > 0 and "fusion replay in.fstream" in rout
    finally:
        for p in (rec, svc):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
        out, err = svc.communicate(timeout=120)
    assert svc.returncode == 0, err
    assert re.search(r"stopped after .*: received \d+ measurements: \d+ applied", out), out
    assert "wrote rec/" in out and ".fstream" in out
    assert "Traceback" not in err


def test_serve_prints_every_threads_stack_on_sigusr1_and_goes_on(tmp_path: Path) -> None:
    """`kill -USR1` on a running service: every thread's stack on stderr (the loop's among them),
    and the service still serves and stops cleanly."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    svc = start("fusion", "serve", "-c", str(SERVICE_TOML), "-l", ep, "--recordings", "rec", cwd=tmp_path)
    try:
        assert svc.stdout.readline().startswith("fusion serving namespace 'demo'")  # type: ignore[union-attr]
        # the line is printed just before the loop starts: a status round trip first, so that the
        # signal finds the loop running even on a loaded machine (it once came before: no loop frame)
        assert run("fusion", "status", "-e", ep, "--json", cwd=tmp_path).returncode == 0
        svc.send_signal(signal.SIGUSR1)
        time.sleep(0.5)
        assert svc.poll() is None, "the service stopped on SIGUSR1"
        st = run("fusion", "status", "-e", ep, "--json", cwd=tmp_path)
        assert st.returncode == 0 and json.loads(st.stdout)["type"] == "status", st.stderr
    finally:
        out, err = stop(svc)
    assert svc.returncode == 0, err
    assert "Thread 0x" in err and "most recent call first" in err, err
    assert re.search(r'File ".*fusion/service\.py", line \d+ in run', err), err
    assert "stopped after" in out
