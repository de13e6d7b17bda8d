"""Running the real console scripts (`fusion`, `fusion-publish` of this venv) in a subprocess."""

from __future__ import annotations

import fcntl
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

BIN = Path(sys.executable).parent
ROOT = Path(__file__).resolve().parents[2]
SERVICE_TOML = ROOT / "configs" / "service.toml"


def script(name: str) -> str:
    path = BIN / name
    assert path.exists(), f"{path} missing: install the package (pip install -e .)"
    return str(path)


def run(*argv: str, cwd: Path, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    """Run `fusion ...` or `fusion-publish ...` to the end, output captured (a pipe, not a terminal)."""
    return subprocess.run([script(argv[0]), *argv[1:]], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL, check=False)


def start(*argv: str, cwd: Path) -> subprocess.Popen[str]:
    return subprocess.Popen([script(argv[0]), *argv[1:]], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, text=True)


def stop(proc: subprocess.Popen[str], *, timeout_s: float = 30.0) -> tuple[str, str]:
    """Ctrl-C (SIGINT), then its (stdout, stderr) once it has exited. One still running after
    timeout_s is asked for its threads' stacks (SIGUSR1: `fusion serve` prints them to stderr),
    killed, and fails the test with the end of its stderr: where it was stuck."""
    proc.send_signal(signal.SIGINT)
    try:
        return proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(1.0)
        proc.kill()
        _, err = proc.communicate(timeout=10)
        raise AssertionError(f"{proc.args[0]} did not stop within {timeout_s} s of SIGINT; the end of its "
                             f"stderr, with its threads' stacks at the timeout:\n{err[-8000:]}") from None


def one_error_line(r: subprocess.CompletedProcess[str]) -> str:
    """The single line a failed command printed on stderr (and no traceback)."""
    assert "Traceback" not in r.stderr, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    return lines[0]


def run_on_terminal(*argv: str, cwd: Path, timeout: float = 120.0) -> tuple[int, str, str]:
    """Run with stderr on a pseudo-terminal of 120 columns (stdout a pipe): (code, stdout, terminal text)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    p = subprocess.Popen([script(argv[0]), *argv[1:]], cwd=cwd, stdout=subprocess.PIPE, stderr=slave,
                         stdin=subprocess.DEVNULL)
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                seen += chunk
            elif p.poll() is not None:
                break
        out = p.stdout.read().decode()  # type: ignore[union-attr]
        code = p.wait(timeout=max(1.0, deadline - time.monotonic()))
    finally:
        os.close(master)
        if p.poll() is None:
            p.kill()
    return code, out, seen.decode(errors="replace")
