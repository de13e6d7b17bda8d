"""Fixed-lag smoothing in the live service ([publication] smooth_lag), through the real path:
with late measurements (revisions, insertions), the subscriber's view ends up with x_k|k+L of
the final estimates."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.config import PublicationConfig
from fusion.core.smoother import rts_smooth
from fusion.fixed_lag import FixedLagSmoother
from fusion.io import wire
from fusion.io.streamfile import StreamReader
from fusion.pipeline import Pipeline
from fusion.smoothing import Histories, track_predictions
from fusion.tracking.tracker import Tracker
from publishers.stream import build_stream
from tests.service.harness import (
    Collector,
    client,
    held_back,
    latest,
    publish_holding_back,
    running_service,
    scenario_config,
)

LAG = 3


def test_fixed_lag_smoothed_estimates_on_the_wire(tmp_path: Path) -> None:
    spec, cfg = scenario_config("mix")
    cfg = msgspec.structs.replace(cfg, publication=PublicationConfig(smooth_lag=LAG))
    spec = msgspec.structs.replace(spec, duration_s=8.0)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    with running_service(cfg, tmp_path) as (svc, endpoint):
        s = client(endpoint)
        try:
            col = Collector(s, f"fusion/{cfg.namespace}/smoothed/*", m.decode_estimate)
            # jittered arrivals, and measurements of 7.0-7.6 s held back until the rest is handled: late data
            publish_holding_back(s, svc, samples, held_back(7_000_000_000, 7_600_000_000), speed=20.0)
            assert svc.wait_idle(timeout_s=60.0)
            got = col.wait_for(svc.outbox.smoothed)
        finally:
            s.close()
    assert len(got) == svc.outbox.smoothed > 0
    assert svc.tracker.counts.late_applied > 0
    assert svc.tracker.counts.replays > 0, "late data should have rewound the tracker"
    view = {k: e for k, e in latest(got).items() if e.status == "confirmed"}
    # offline: the final estimates of the same input, each confirmed one smoothed over the next LAG
    tracker = Tracker(cfg.tracker)
    hist = Histories()
    pipe = Pipeline(tracker, wire.Codec(cfg.namespace), sink=hist)
    for rec in StreamReader(tmp_path / "live.fstream"):
        pipe.ingest([rec])
    want = {}
    for tid, h in hist.tracks().items():
        if len(h) <= LAG:
            continue
        x, P, xp, Pp, F = track_predictions(h, tracker)
        for i in range(len(h) - LAG):
            if h[i].status == "confirmed":
                xs, Ps = rts_smooth(*(a[i:i + LAG + 1] for a in (x, P, xp, Pp, F)))
                want[(tid, h[i].t_ns, h[i].sensor_id)] = (xs[0], Ps[0])
    assert len(want) > 100
    assert sorted(view) == sorted(want)
    for k, (x, P) in want.items():
        np.testing.assert_allclose(view[k].state, x, rtol=1e-9, atol=1e-9, err_msg=str(k))
        np.testing.assert_allclose(view[k].cov, P.ravel(), rtol=1e-9, atol=1e-9, err_msg=str(k))


def test_the_lag_must_be_positive() -> None:
    _, cfg = scenario_config("radar2d")
    with pytest.raises(ValueError, match="at least 1"):
        FixedLagSmoother(Tracker(cfg.tracker), 0)
