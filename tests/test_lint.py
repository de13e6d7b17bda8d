"""The code passes ruff with the project's rules (pyproject.toml [tool.ruff]): CI runs the README's
test command only, so a style rule that is not checked here is not checked at all (a line over
the length limit once reached main that way)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_code_passes_ruff() -> None:
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise", "."],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert "No module named ruff" not in run.stderr, "ruff is a test dependency: pip install -e '.[test]'"
    assert run.returncode == 0, f"ruff check found problems:\n{run.stdout}{run.stderr}"
