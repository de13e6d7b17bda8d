"""Every user mistake and expected failure ends in one line on stderr with its own exit code,
through the real console scripts; no traceback unless -v/--debug asks for one."""

from __future__ import annotations

import re
import socket
import time
from pathlib import Path
from typing import Any

import pytest

from fusion.cli.runner import Exit
from fusion.io.zenoh_bus import free_tcp_port
from tests.cli.helpers import SERVICE_TOML, one_error_line, run, start

GOOD_SENSORS = '[[tracker.sensors]]\nid = "cam1"\nkind = "cartesian"\nstd_m = [1.0, 1.0]\n'


@pytest.mark.parametrize(("argv", "expected"), [
    (["fusion", "demo", "--scenario", "nosuch"], r"no scenario 'nosuch'.*choose from .*mix.*radar2d"),
    (["fusion", "demo", "-s", "mxi"], r"did you mean 'mix'\?"),
    (["fusion-publish", "--scenario", "nosuch"], r"no scenario 'nosuch'.*choose from .*mix"),
    (["fusion", "demo", "--speed", "fast"], r"--speed: 'fast' is neither a number nor 'max'"),
    (["fusion", "demo", "--duration", "-5"], r"--duration: must be a positive number of seconds, got '-5'"),
    (["fusion", "demo", "--seed", "-1"], r"--seed: must be 0 or more"),
    (["fusion", "demo", "-o", "out.txt"], r"ends in \.rrd"),
    (["fusion", "serve"], r"required: -c/--config"),
    (["fusion", "nosuch"], r"invalid choice: 'nosuch'"),
    (["fusion"], r"which command\? one of demo, serve, record, status, tracks, replay, inspect \(start with `fusion "
                 r"demo`\)"),
    (["fusion", "status", "-e", "127.0.0.1:7447"], r"not a Zenoh endpoint.*tcp/127\.0\.0\.1:7447"),
    (["fusion", "status", "-m", "peer"], r"a peer needs an endpoint to listen on: add -l"),
    (["fusion", "record", "-n", "a/b"], r"a namespace is 1-64 of letters"),
    (["fusion-publish", "-s", "mix", "--speed", "0"], r"--speed: must be a positive factor"),
], ids=["scenario", "scenario-near-miss", "publish-scenario", "speed", "duration", "seed", "out-suffix",
        "missing-config", "command", "no-command", "endpoint", "peer-without-listen", "namespace", "publish-speed"])
def test_bad_arguments(argv: list[str], expected: str, tmp_path: Path) -> None:
    r = run(*argv, cwd=tmp_path)
    assert r.returncode == Exit.USAGE, r.stderr
    line = one_error_line(r)
    assert re.search(expected, line), line
    assert line.startswith(f"{argv[0]}") and "--help" in line
    assert not (tmp_path / "recordings").exists(), "nothing is written for a bad command line"


def _file_cases(tmp: Path) -> dict[str, tuple[list[str], str]]:
    (tmp / "folder").mkdir()
    (tmp / "a.fstream").write_bytes(b"FUSIONST\x01\x00\x02\x00\x00\x00{}")
    (tmp / "a.rrd").write_bytes(b"RRF2\x00\x00\x00\x00")
    (tmp / "notes.txt").write_text("hello\n")
    (tmp / "empty.rrd").write_bytes(b"")
    return {
        "inspect-missing": (["fusion", "inspect", "missing.rrd"], r"missing\.rrd: no such recording; fusion demo"),
        "inspect-folder": (["fusion", "inspect", "folder"], r"folder: no recordings found"),  # a folder is a set
        "inspect-stream": (["fusion", "inspect", "a.fstream"], r"input stream.*fusion replay a\.fstream"),
        "inspect-text": (["fusion", "inspect", "notes.txt"], r"not a Rerun recording"),
        "inspect-empty": (["fusion", "inspect", "empty.rrd"], r"empty\.rrd: the file is empty"),
        "replay-missing": (["fusion", "replay", "missing.fstream"], r"missing\.fstream: no such stream file"),
        "replay-recording": (["fusion", "replay", "a.rrd"], r"Rerun recording.*fusion inspect a\.rrd"),
        "serve-missing-config": (["fusion", "serve", "--config", "missing.toml"],
                                 r"missing\.toml: no such configuration file; the shipped one is configs/service"),
        "publish-missing-config": (["fusion-publish", "-c", "missing.toml"], r"missing\.toml: no such scenario file"),
        "demo-unwritable": (["fusion", "demo", "-s", "cv1d_a", "-o", "notes.txt/x.rrd"],
                            r"notes\.txt/x\.rrd: cannot write the recording there \(not a folder\); choose another"),
        "replay-unwritable": (["fusion", "replay", "real.fstream", "-o", "notes.txt/y.rrd"],
                              r"notes\.txt/y\.rrd: cannot write the recording there"),
        "record-unwritable": (["fusion", "record", "-o", "notes.txt/z.fstream"],
                              r"notes\.txt/z\.fstream: cannot write the stream file there"),
    }


@pytest.mark.parametrize("case", [
    "inspect-missing", "inspect-folder", "inspect-stream", "inspect-text", "inspect-empty", "replay-missing",
    "replay-recording", "serve-missing-config", "publish-missing-config", "demo-unwritable", "replay-unwritable",
    "record-unwritable"])
def test_missing_or_wrong_files(case: str, tmp_path: Path) -> None:
    argv, expected = _file_cases(tmp_path)[case]
    if case == "replay-unwritable":  # a real stream file, so that only the output is wrong
        from fusion.io.streamfile import StreamWriter

        StreamWriter(tmp_path / "real.fstream", namespace="demo").close()
    r = run(*argv, cwd=tmp_path)
    assert r.returncode == Exit.FILE, r.stderr
    line = one_error_line(r)
    assert re.search(expected, line), line
    assert not (tmp_path / "recordings").exists(), "nothing is written when a file is wrong"
    assert not list(tmp_path.glob(".fusion-probe-*")), "the probe of a folder leaves nothing behind"


@pytest.mark.parametrize(("text", "expected"), [
    (GOOD_SENSORS + '[tracker.motion]\nmodel = "imm-cv"\n',
     r"bad\.toml:6: tracker\.motion\.model: 'imm-cv' is not one of 'ca', 'ct', 'custom', 'cv', 'imm'; "
     r"did you mean 'imm'\?"),
    ('namspace = "x"\n' + GOOD_SENSORS,
     r"bad\.toml:1: namspace: unknown key 'namspace'; did you mean 'namespace'\? \(keys here: tracker, namespace"),
    (GOOD_SENSORS + '[[tracker.sensors]]\nid = "r"\nkind = "radr"\n',
     r"bad\.toml:7: tracker\.sensors\[1\]\.kind: 'radr' is not one of 'cartesian', 'radar', 'custom'; "
     r"did you mean 'radar'\?"),
    (GOOD_SENSORS + "[tracker.gate]\nprobability = 2.0\n",
     r"bad\.toml:6: tracker\.gate\.probability: Expected float < 1\.0, got 2\.0"),
    ('namespace = "x"\n', r"bad\.toml: required key 'tracker' is missing"),
    ("namespace = \n", r"bad\.toml:1: malformed TOML"),
], ids=["enum", "unknown-key", "list-item-enum", "bound", "missing", "malformed"])
def test_config_errors_name_file_line_key(text: str, expected: str, tmp_path: Path) -> None:
    (tmp_path / "bad.toml").write_text(text)
    r = run("fusion", "serve", "-c", "bad.toml", "-l", f"tcp/127.0.0.1:{free_tcp_port()}", cwd=tmp_path)
    assert r.returncode == Exit.CONFIG, r.stderr
    line = one_error_line(r)
    assert re.search(expected, line), line
    assert not (tmp_path / "recordings").exists()


def test_scenario_file_errors_through_fusion_publish(tmp_path: Path) -> None:
    """The same formatting for scenario files; the [service] table's keys are named in full."""
    text = (Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "radar2d.toml").read_text()
    bad = re.sub(r"(?m)^\[scenario\]$", "[scenario]\ndurration_s = 5.0", text, count=1)
    assert bad != text
    (tmp_path / "s.toml").write_text(bad)
    r = run("fusion-publish", "-c", "s.toml", cwd=tmp_path)
    assert r.returncode == Exit.CONFIG, r.stderr
    assert re.search(r"s\.toml:\d+: scenario\.durration_s: unknown key 'durration_s'; did you mean 'duration_s'\?",
                     one_error_line(r))


def test_debug_shows_the_traceback_and_flags_work_after_the_command(tmp_path: Path) -> None:
    r = run("fusion", "inspect", "missing.rrd", "-v", cwd=tmp_path)
    assert r.returncode == Exit.FILE
    assert "Traceback" in r.stderr and r.stderr.strip().splitlines()[-1].startswith("fusion inspect: error:")
    r2 = run("fusion", "--debug", "inspect", "missing.rrd", cwd=tmp_path)
    assert r2.returncode == Exit.FILE and "Traceback" in r2.stderr


def test_nothing_to_connect_to(tmp_path: Path) -> None:
    """record, status and fusion-publish with nobody listening: say to start the service."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    for argv in (["fusion", "record", "-e", ep, "--duration", "1"], ["fusion", "status", "-e", ep],
                 ["fusion-publish", "-s", "cv1d_a", "-e", ep]):
        r = run(*argv, cwd=tmp_path)
        assert r.returncode == Exit.CONNECT, (argv, r.stderr)
        line = one_error_line(r)
        assert f"cannot connect to {ep}: nothing is listening there; start the service first (fusion serve" in line
        assert ".rs:" not in line, "no Rust source paths"
    assert not list(tmp_path.rglob("*.fstream")), "record wrote nothing"


def test_serve_as_a_client_with_nothing_to_connect_to(tmp_path: Path) -> None:
    """`fusion serve -m client` retries for --connect-wait (saying so in its log), then gives up
    with a hint for serve itself (not "start the service first"), and writes nothing."""
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    config = str(SERVICE_TOML)
    t0 = time.monotonic()
    r = run("fusion", "serve", "-c", config, "-m", "client", "-e", ep, "--connect-wait", "0.5", cwd=tmp_path)
    assert r.returncode == Exit.CONNECT, r.stderr
    assert time.monotonic() - t0 >= 0.5
    assert re.search(r"connecting: nothing listens at .* \(attempt 2\); retrying", r.stderr), r.stderr
    last = r.stderr.strip().splitlines()[-1]
    assert f"fusion serve: error: cannot connect to {ep}: nothing is listening there" in last
    assert "start the peer or router it joins first" in last and "start the service first" not in last
    r = run("fusion", "serve", "-q", "-c", config, "-m", "client", "-e", ep, "--connect-wait", "0", cwd=tmp_path)
    assert r.returncode == Exit.CONNECT and "start the peer or router" in one_error_line(r)
    assert not list(tmp_path.rglob("*.rrd")) and not list(tmp_path.rglob("*.fstream")), "serve wrote files"


def test_no_service_answers(zenoh_hub: tuple[Any, str], tmp_path: Path) -> None:
    """Something listens, but no fusion service: status and tracks say so (exit 7)."""
    _, ep = zenoh_hub
    for cmd in ("status", "tracks"):
        r = run("fusion", cmd, "-e", ep, "--timeout", "0.5", cwd=tmp_path)
        assert r.returncode == Exit.NO_ANSWER, r.stderr
        assert re.search(r"no fusion service answered on fusion/demo/(status|snapshot) within 0\.5 s; "
                         r"is `fusion serve` running with namespace 'demo'\?", one_error_line(r))


def test_busy_port_fails_fast_and_writes_nothing(tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = run("fusion", "serve", "-c", str(SERVICE_TOML), "-l", f"tcp/127.0.0.1:{port}", "--recordings", "rec",
                cwd=tmp_path)
    assert r.returncode == Exit.LISTEN, r.stderr
    line = one_error_line(r)
    assert line == (f"fusion serve: error: cannot listen on tcp/127.0.0.1:{port}: address already in use; another "
                    "program (perhaps another `fusion serve`) listens there: stop it, or listen elsewhere with "
                    "-l tcp/127.0.0.1:PORT")
    assert not (tmp_path / "rec").exists() or not any((tmp_path / "rec").iterdir()), "no files before the start"


def test_version_help_and_exit_codes(tmp_path: Path) -> None:
    r = run("fusion", "--version", cwd=tmp_path)
    assert r.returncode == 0 and re.match(r"fusion \d+\.\d+\.\d+ \(eclipse-zenoh 1\.", r.stdout), r.stdout
    h = run("fusion", "--help", cwd=tmp_path)
    assert h.returncode == 0
    for code in Exit:
        assert re.search(rf"(?m)^\s+{int(code)}  \S", h.stdout), f"exit code {int(code)} undocumented"
    p = run("fusion-publish", "--help", cwd=tmp_path)
    assert p.returncode == 0 and "exit codes:" in p.stdout and "-m {peer,client}, --mode" in p.stdout


@pytest.mark.parametrize("cmd", ["demo", "serve", "record", "status", "tracks", "replay", "inspect"])
def test_every_command_explains_itself(cmd: str, tmp_path: Path) -> None:
    r = run("fusion", cmd, "--help", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "examples:" in r.stdout and f"fusion {cmd}" in r.stdout.split("examples:")[1]
    # every option that takes a value and is not required states its default
    for m in re.finditer(r"(?ms)^  (-\S.*?)(?=^  -|\n\n|\Z)", r.stdout.split("examples:")[0]):
        opt = " ".join(m.group(1).split())
        takes_value = re.match(r"(-\w, )?--?[\w-]+ [A-Z{]", opt) is not None
        if takes_value and "(required)" not in opt and not opt.startswith(("-m ", "-e ", "-l ")):
            assert "default" in opt, f"{cmd}: {opt}"


def test_ctrl_c_ends_a_recording(tmp_path: Path) -> None:
    """Ctrl-C is how `fusion record` ends: exit 0, what was recorded, no KeyboardInterrupt."""
    import signal
    import time

    p = start("fusion", "record", "-l", f"tcp/127.0.0.1:{free_tcp_port()}", "-o", "r.fstream", cwd=tmp_path)
    line = p.stdout.readline()  # type: ignore[union-attr]
    assert line.startswith("recording "), line
    time.sleep(0.3)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err  # Ctrl-C is how a recording ends
    assert "Traceback" not in err and "recorded 0 samples to r.fstream" in out
    assert "is a publisher running" in out
    assert (tmp_path / "r.fstream").exists()


def test_replay_says_its_configuration_and_hints_when_it_has_none_of_the_sensors(tmp_path: Path) -> None:
    """A .jsonl of cv1d_d's messages has no namespace: replayed without -c it runs with the
    demo namespace's scenario (mix), which has none of its sensors nor its control source. The
    summary names the configuration used, tells the refused control inputs from the measurements
    and says what to do; with -c it applies everything."""
    from fusion import messages as m
    from publishers.spec import load_scenario_file, scenario_path
    from publishers.stream import build_stream

    samples, _ = build_stream(load_scenario_file(scenario_path("cv1d_d")).scenario, namespace="x")
    (tmp_path / "s.jsonl").write_bytes(b"".join(m.encode_json(m.decode_any(s.payload)) + b"\n" for s in samples))
    r = run("fusion", "replay", "s.jsonl", "-o", "a.rrd", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    used = re.search(r"replayed 300 samples in .* with (\S*configs/scenarios/mix\.toml): .* 0 applied", r.stdout)
    assert used, r.stdout
    assert "configures none of the stream's sensors" in r.stdout and "fusion replay s.jsonl -c FILE" in r.stdout
    # the refused control inputs are said as such, not counted among the measurements
    assert ("received 100 measurements and 100 control inputs: 0 applied, 0 duplicates dropped, 200 refused "
            "(unknown_sensor 200); of the duplicates and refused: control inputs 100") in r.stdout, r.stdout
    r = run("fusion", "replay", "s.jsonl", "-o", "b.rrd", "-c", str(scenario_path("cv1d_d")), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "received 100 measurements and 100 control inputs: 100 applied" in r.stdout, r.stdout
    assert "hint" not in r.stdout
