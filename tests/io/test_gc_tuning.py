"""settle_garbage_collector freezes start-up's objects and raises the young threshold only (in a
subprocess: the test process keeps its collector)."""

from __future__ import annotations

import subprocess
import sys


def test_settle_freezes_and_raises_young_threshold() -> None:
    code = (
        "import gc, json\n"
        "from fusion.io.gc_tuning import settle_garbage_collector\n"
        "before = gc.get_threshold()\n"
        "settle_garbage_collector(12345)\n"
        "print(json.dumps([before, gc.get_threshold(), gc.get_freeze_count()]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    import json

    before, after, frozen = json.loads(out)
    assert after == [12345, before[1], before[2]]
    assert frozen > 1000  # the interpreter's and fusion's start-up objects
