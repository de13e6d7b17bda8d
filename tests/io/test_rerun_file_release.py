"""A closed RerunFile leaves nothing behind in rerun-sdk. rerun keeps every RecordingStream it made
in a process-wide list until `flush_and_cleanup_orphaned_recordings`, and a blueprint's stream
is held by its own in-memory sink: each file a rotating recording closed held ~0.7 MB (160
entities) and each layout it sent ~0.4 MB, for the life of the process, until RerunFile.close
released the closed streams and send_layout its blueprint's (fusion.io.rerun_file). Measured as
resident memory over 35 files of 160 entities and 3 layouts each, in a fresh process (mimalloc
settled as the service settles it), as shipped and, as the control, with rerun's own calls; and
a caller's global recording (`rr.init`) survives the release."""

from __future__ import annotations

import os
import subprocess
import sys

FILES = """
import os, sys, tempfile
from pathlib import Path
from fusion.io.allocator import settle_allocator
settle_allocator()
import numpy as np
from fusion.io import rerun_file
from fusion.io.columns import Column
if sys.argv[1] == "kept":  # the control: rerun's own calls
    rerun_file.release_closed_streams = lambda: None
    rerun_file.send_blueprint = lambda rec, layout: rec.send_blueprint(layout)

def rss_mb():
    for line in open(f"/proc/{os.getpid()}/status"):
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024

d = Path(tempfile.mkdtemp())
for k in range(40):
    f = rerun_file.RerunFile(d / f"f{k}.rrd", recording_id=f"f{k}", application_id="fusion", meta={"k": k})
    cols = {f"counts/c{e:03d}": Column("scalars", width=1) for e in range(160)}
    for c in cols.values():
        for t in range(50):
            c.add(k * 50 + t, k * 50 + t, k * 50 + t, v=[float(t)])
    f.send(cols, lambda: None)
    for viewed in ([], ["a"], ["a", "b"]):  # three layouts: the viewed tracks change
        f.send_layout(ndim=2, axes=["x", "y"], viewed=viewed, centre=[0.0, 0.0, 0.0], extent_m=10.0)
    f.close()
    (d / f"f{k}.rrd").unlink()
    if k == 4:
        base = rss_mb()
print((rss_mb() - base) / 35)
"""

GLOBAL = """
import tempfile
from pathlib import Path
import rerun as rr
from fusion.io import rerun_file
rr.init("caller", recording_id="callers-own", spawn=False)
f = rerun_file.RerunFile(Path(tempfile.mkdtemp()) / "f.rrd", recording_id="f", application_id="fusion", meta={})
f.close()
f.close()  # a second close does nothing
g = rr.get_global_data_recording()
print(None if g is None else g.get_recording_id())
"""


def _run(code: str, *args: str) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MIMALLOC_")}
    r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout.strip()


def test_a_closed_file_s_stream_is_freed() -> None:
    released = float(_run(FILES, "released"))
    kept = float(_run(FILES, "kept"))
    assert released < 0.15, f"{released:.3f} MB of resident memory a closed file ({kept:.3f} with rerun's own calls)"
    assert kept > 0.8, f"the control: {kept:.3f} MB a file with rerun's calls (expected ~1.8: rerun keeps the streams)"


def test_the_caller_s_global_recording_survives_the_release() -> None:
    assert _run(GLOBAL) == "callers-own"
