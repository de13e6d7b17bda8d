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


def _imports(path: Path) -> set[str]:
    """Every module a source file imports (absolute names; relative imports are not used here)."""
    import ast

    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package.replace(".", "/")).rglob("*.py"))


def _module(path: Path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts)


@pytest.mark.parametrize("package", ["fusion.tracking", "publishers"])
def test_tracking_and_publishers_load_no_zenoh_or_rerun(package: str) -> None:
    """Tracking has no I/O; the publishers' simulation is pure (only their CLI and loop talk to
    zenoh, and they import it inside functions)."""
    mods = [_module(p) for p in _sources(package) if p.name != "__main__.py"]
    code = (
        "import importlib, json, sys\n"
        f"for m in {mods!r}: importlib.import_module(m)\n"
        "print(json.dumps(sorted(k for k in sys.modules if k.split('.')[0] in ('zenoh', 'rerun'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60,
                         check=False)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [], f"{package} loaded zenoh or rerun"


def test_only_the_command_line_imports_publishers() -> None:
    allowed = {"fusion.__main__"}
    bad = {_module(p): sorted(m for m in _imports(p) if m.split(".")[0] == "publishers")
           for p in _sources("fusion")
           if _module(p) not in allowed and not _module(p).startswith("fusion.cli")}
    assert {k: v for k, v in bad.items() if v} == {}


def test_dependencies_point_inward() -> None:
    """core imports nothing of fusion but errors; tracking nothing of io, service or pipeline;
    io never the pipeline or the service."""
    rules = {
        "fusion.core": ("fusion.tracking", "fusion.io", "fusion.pipeline", "fusion.service", "fusion.config",
                        "fusion.messages"),
        "fusion.tracking": ("fusion.io", "fusion.pipeline", "fusion.service", "fusion.messages", "fusion.replay"),
        "fusion.io": ("fusion.pipeline", "fusion.service", "fusion.replay"),
    }
    found = {}
    for package, forbidden in rules.items():
        for p in _sources(package):
            hits = sorted(m for m in _imports(p) if m.startswith(forbidden))
            if hits:
                found[_module(p)] = hits
    assert found == {}
