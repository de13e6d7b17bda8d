"""Fixtures for the recording tests: rerun's analytics state goes to a temporary folder."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest


@pytest.fixture(autouse=True, scope="session")
def _rerun_home(tmp_path_factory: pytest.TempPathFactory) -> None:
    home = tmp_path_factory.mktemp("xdg")
    os.environ["XDG_CONFIG_HOME"] = str(home)
    os.environ["XDG_DATA_HOME"] = str(home)


@pytest.fixture(scope="session")
def rerun_cli() -> Path:
    """The real rerun binary (not the Python wrapper)."""
    import rerun_cli

    exe = Path(rerun_cli.__file__).parent / "rerun"
    if not exe.exists():  # pragma: no cover - depends on the wheel layout
        found = shutil.which("rerun")
        assert found, "the rerun CLI is not installed"
        exe = Path(found)
    return exe
