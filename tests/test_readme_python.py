"""README.md's example of the tracker from Python runs as shown, from the repository's root."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _block(title: str) -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split(f"## {title}\n", 1)[1].split("\n## ", 1)[0]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


def test_the_tracker_from_python_runs_as_shown() -> None:
    r = subprocess.run([sys.executable, "-c", _block("The tracker from Python")], cwd=ROOT, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    first, second = r.stdout.splitlines()
    assert " confirmed [" in first  # the target's track, confirmed, and its state
    assert second.startswith("(Replay(") and "n_scans=7" in second  # the late one replayed the scans after it
