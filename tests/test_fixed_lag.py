"""fusion.fixed_lag on its own: late data revise and retract smoothed outputs so that the
subscriber's view is the same for any arrival order."""

from __future__ import annotations

import numpy as np

from fusion.fixed_lag import FixedLagSmoother
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.results import Estimate
from fusion.tracking.tracker import Tracker
from publishers.stream import build_stream
from tests.service.harness import scenario_config


def _view(records: list[tuple[int, str, bytes]], batch: int) -> tuple[dict, list[Estimate]]:
    _, cfg = scenario_config("radar2d")
    tracker = Tracker(cfg.tracker)
    pipe = Pipeline(tracker, wire.Codec(cfg.namespace))
    fl = FixedLagSmoother(tracker, 4)
    sent: list[Estimate] = []
    for i in range(0, len(records), batch):
        sent.extend(fl.update(pipe.ingest(records[i:i + batch]).result.estimates))
    view: dict = {}
    for e in sent:
        if e.status == "retracted":
            view.pop(e.key, None)
        else:
            view[e.key] = e
    return {k: e for k, e in view.items() if e.status == "confirmed"}, sent


def test_the_view_does_not_depend_on_arrival_order() -> None:
    spec, cfg = scenario_config("radar2d")
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    recs = [(0, s.key, s.payload) for s in samples if "/meas/" in s.key]
    rng = np.random.default_rng(8)
    late = list(recs)
    for i in range(0, len(late) - 3, 4):  # every 4th measurement arrives 3 places late
        j = i + int(rng.integers(1, 4))
        late[i], late[j] = late[j], late[i]
    in_order, _ = _view(recs, 1)
    shuffled, sent = _view(late, 1)
    assert any(e.revision > 0 for e in sent), "late data should revise published smoothed estimates"
    assert sorted(in_order) == sorted(shuffled) and len(in_order) > 150
    for k, e in in_order.items():
        np.testing.assert_allclose(shuffled[k].x, e.x, rtol=1e-9, atol=1e-9, err_msg=f"seed=8 {k}")
        np.testing.assert_allclose(shuffled[k].P, e.P, rtol=1e-9, atol=1e-9, err_msg=f"seed=8 {k}")
