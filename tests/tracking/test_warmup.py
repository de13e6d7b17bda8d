"""fusion.tracking.warmup: after warm_up(config), real data of that configuration compile nothing.

Each case runs in a fresh interpreter (numba's compiled signatures are per process): warm_up
on the configuration, then a note of every numba dispatcher's compiled signatures in fusion's
modules, then a scenario's simulated stream through a Tracker of the same configuration (its first 3000
measurements as the wire decodes them, in arrival order with 10 % of them one place late, so
replays run, in batches of 4 as the service drains a slow stream), then the
signatures again: none may have been added. A warm-up that missed a path (a measurement dimension,
the replay, a batch of several scans) fails here, naming the kernels it missed.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

CHILD = r"""
import json, sys
import numpy as np
from numba.core.dispatcher import Dispatcher
from fusion.io.wire import detection_of
from fusion.tracking.tracker import Tracker
from fusion.tracking.warmup import warm_up
import fusion.messages as m
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream

def compiled():
    out = {}
    for name, mod in sorted(sys.modules.items()):
        if name.startswith("fusion") and mod is not None:
            for attr, obj in sorted(vars(mod).items()):
                if isinstance(obj, Dispatcher):
                    out[obj.py_func.__module__ + "." + obj.py_func.__qualname__] = [str(s) for s in obj.signatures]
    return out

sf = load_scenario_file(scenario_path(sys.argv[1]))
cfg = sf.service.tracker
ran = warm_up(cfg)
before = compiled()
samples, _ = build_stream(sf.scenario, namespace="w")
dets = [detection_of(m.decode_measurement(s.payload)) for s in samples if "/meas/" in s.key][:3000]
rng = np.random.default_rng(0)
order = list(range(len(dets)))
for i in range(20, len(dets) - 2):  # 10 % of them swapped with the one after: one measurement late
    if rng.random() < 0.1:
        order[i], order[i + 1] = order[i + 1], order[i]
tr = Tracker(cfg)
for k in range(0, len(order), 4):  # small batches, as the service drains a slow stream
    tr.process([dets[i] for i in order[k:k + 4]])
tr.predict(max(d.t_ns for d in dets) + 50_000_000)
after = compiled()
new = {k: [s for s in v if s not in before.get(k, [])] for k, v in after.items()}
print(json.dumps({"warm": list(ran), "late": tr.counts.late_applied, "confirmed": len(tr.confirmed()),
                  "new": {k: v for k, v in new.items() if v}}))
"""


@pytest.mark.parametrize("scenario", ["mix", "radar2d", "helix3d"])
def test_nothing_compiles_after_warm_up(scenario: str) -> None:
    r = subprocess.run([sys.executable, "-c", CHILD, scenario], cwd=ROOT, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["warm"][0] > 0 and got["confirmed"] > 0 and got["late"] > 0, got  # the stream did exercise it
    assert got["new"] == {}, f"compiled after the warm-up: {got['new']}"
