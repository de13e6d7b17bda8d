"""The live service's recording, written on its own thread ([recording] background, the default)
or on the loop: either way the file holds what a replay of the service's own input records (the
same tracks, errors, consistency figures, OSPA, standing events and counts), the thread runs only
while the service does, and the status says how many rows it still has to write."""

from __future__ import annotations

import threading
from pathlib import Path

import msgspec
import pytest

from fusion.io.inspect import summarise
from fusion.replay import replay
from publishers.stream import build_stream
from tests.service.harness import (
    EstimateCollector,
    client,
    held_back,
    publish_holding_back,
    running_service,
    scenario_config,
)


def _figures(path: Path) -> dict:
    s = summarise(path)
    tracks = [(t.track_id, t.first_t_ns, t.last_t_ns, t.position_rmse, t.mean_nis, t.mean_nees) for t in s.tracks]
    return {"tracks": tracks, "rmse": s.position_rmse, "ospa": s.ospa_m, "gospa": s.gospa_m,
            "events": s.events_net, "applied": s.counts.get("applied"), "truth": s.counts.get("truth"),
            "nis": s.nis.verdict, "nees": s.nees.verdict, "complete": s.complete}


@pytest.mark.parametrize("background", [True, False], ids=["thread", "loop"])
def test_the_live_recording_holds_what_a_replay_records(background: bool, tmp_path: Path) -> None:
    spec, cfg = scenario_config("mix")
    spec = msgspec.structs.replace(spec, duration_s=8.0)
    cfg = msgspec.structs.replace(cfg, recording=msgspec.structs.replace(cfg.recording, background=background))
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    with running_service(cfg, tmp_path) as (svc, endpoint):
        threads = {t.name for t in threading.enumerate()}
        sub = client(endpoint)
        try:
            col = EstimateCollector(sub, cfg.namespace)
            pub = client(endpoint)
            try:
                # measurements of 7.0-7.6 s held back until the rest is handled: replays on any machine
                publish_holding_back(pub, svc, samples, held_back(7_000_000_000, 7_600_000_000), speed=20.0)
            finally:
                pub.close()
            assert svc.wait_idle(timeout_s=60.0)
            col.all_of(svc)
            st = svc.status_dict()
        finally:
            sub.close()
    assert ("fusion-recording" in threads) == background
    left = {t.name for t in threading.enumerate()}
    assert "fusion-recording" not in left, "the recording's thread outlived the service"
    assert st["recording_queue"] == 0, "wait_idle returned with rows still to write"
    assert svc.tracker.counts.late_applied > 0, "no late measurements: the run does not exercise replays"
    replay(tmp_path / "live.fstream", out=tmp_path / "replayed.rrd")
    live, replayed = _figures(tmp_path / "live.rrd"), _figures(tmp_path / "replayed.rrd")
    assert live == replayed
    assert live["complete"] and len(live["tracks"]) >= 5 and live["applied"] > 500
