"""settle_allocator reaches rerun's own mimalloc (its start-up report, MIMALLOC_VERBOSE=1, names the
option's value), keeps a value the user set, says when it came too late, and `fusion serve`
settles it before anything loads rerun. Subprocesses: mimalloc reads the environment once."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from fusion.io.zenoh_bus import free_tcp_port
from tests.cli.helpers import SERVICE_TOML, script


def _python(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    e = {k: v for k, v in os.environ.items() if not k.startswith("MIMALLOC_")} | {"MIMALLOC_VERBOSE": "1", **env}
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=e, timeout=120)


def _purge_delays(stderr: str) -> set[str]:
    """The purge_delay of every mimalloc that reported starting (rerun's, and pyarrow's if loaded)."""
    return set(re.findall(r"option 'purge_delay': (\d+)", stderr))


SETTLE_THEN_IMPORT = "from fusion.io.allocator import settle_allocator\nprint(settle_allocator())\nimport rerun\n"


def test_settle_sets_the_purge_delay_of_rerun_s_allocator() -> None:
    r = _python(SETTLE_THEN_IMPORT)
    assert r.stdout.strip() == "True"
    assert _purge_delays(r.stderr) == {"0"}, r.stderr[-2000:]


def test_without_it_rerun_keeps_mimalloc_s_default() -> None:
    """The control: the report shows mimalloc's default (so the check above can fail)."""
    r = _python("import rerun\n")
    assert _purge_delays(r.stderr) and "0" not in _purge_delays(r.stderr), r.stderr[-2000:]


def test_a_value_the_user_set_is_kept() -> None:
    r = _python(SETTLE_THEN_IMPORT, MIMALLOC_PURGE_DELAY="250")
    assert _purge_delays(r.stderr) == {"250"}, r.stderr[-2000:]


def test_too_late_once_rerun_is_loaded() -> None:
    r = _python("import rerun\nfrom fusion.io.allocator import settle_allocator\nprint(settle_allocator())\n")
    assert r.stdout.strip() == "False"


def test_fusion_serve_settles_it_before_rerun_loads(tmp_path: Path) -> None:
    ep = f"tcp/127.0.0.1:{free_tcp_port()}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MIMALLOC_")} | {"MIMALLOC_VERBOSE": "1"}
    r = subprocess.run(
        [script("fusion"), "serve", "-c", str(SERVICE_TOML), "-l", ep, "--recordings", "rec", "--duration", "1"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
        stdin=subprocess.DEVNULL,
        check=False,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "recording to rec/" in r.stdout
    assert _purge_delays(r.stderr) == {"0"}, r.stderr[-2000:]
