"""Layering: the estimation core, fusion.models and the scenarios load no I/O library (zenoh, rerun,
msgspec).

Checked in a fresh interpreter, so that nothing the test session imported leaks in.
"""

from __future__ import annotations

import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FORBIDDEN = ("zenoh", "rerun", "msgspec")


def _core_modules() -> list[str]:
    import fusion.core
    import fusion.models

    names = [f"fusion.core.{m.name}" for m in pkgutil.iter_modules(fusion.core.__path__)]
    names += [f"fusion.models.{m.name}" for m in pkgutil.iter_modules(fusion.models.__path__)]
    return [*sorted(names), "fusion.core", "fusion.models", "fusion.errors", "fusion.scenarios"]


def test_core_module_list_is_complete() -> None:
    mods = _core_modules()
    for expected in ("kalman", "ukf", "imm", "motion", "measurement", "gaussian", "checks"):
        assert f"fusion.core.{expected}" in mods, mods
    for expected in ("helix", "loader"):
        assert f"fusion.models.{expected}" in mods, mods


@pytest.mark.parametrize("target", ["all", "fusion.core", "fusion.scenarios"])
def test_core_imports_no_io_libraries(target: str) -> None:
    mods = _core_modules() if target == "all" else [target]
    code = (
        "import importlib, json, sys\n"
        f"for m in {mods!r}: importlib.import_module(m)\n"
        f"print(json.dumps(sorted(k for k in sys.modules if k.split('.')[0] in {FORBIDDEN!r})))\n"
        "print(json.dumps(sorted(k for k in sys.modules if k.startswith('fusion'))))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
        check=False,
    )
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    loaded, fusion_mods = json.loads(lines[-2]), json.loads(lines[-1])
    assert loaded == [], f"importing {mods} loaded {loaded}"
    # the worktree's own package was imported (not another checkout's)
    assert "fusion.core.kalman" in fusion_mods or target != "all"
    where = subprocess.run(
        [sys.executable, "-c", "import fusion; print(fusion.__file__)"], cwd=ROOT,
        capture_output=True, text=True, timeout=60, check=True,
    ).stdout.strip()
    assert Path(where).resolve().is_relative_to(ROOT), where


def test_session_tests_the_worktree_package() -> None:
    import fusion

    assert Path(fusion.__file__).resolve().is_relative_to(ROOT), fusion.__file__
