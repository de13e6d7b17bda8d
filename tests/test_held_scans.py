"""A batch with more to come holds its last scan back (Pipeline.ingest(..., more=True)): the scans a
fixed batch size cuts are run once, whole, instead of run and run again (rescans); what the
consumer ends up with is the same as with any other batching; the held measurements count as not
yet received, so the counts add up after every call; and the service's loop and `fusion replay`
pass `more` (the loop only when a full batch leaves a backlog)."""

from __future__ import annotations

import functools

from bench.recording_cost import CONFIG, batches
from fusion.config import ServiceConfig, load_service_config
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.tracker import Tracker
from tests.tracking.helpers import Consumer, data_counts, track_snapshot


def _records(targets: int, seconds: float) -> tuple[list[tuple[int, str, bytes]], ServiceConfig]:
    """The benchmark's load (bench.recording_cost.batches: radar1 and cam1 scans of every target
    as contiguous bursts, truth at radar scans) for the shipped configuration."""
    service = load_service_config(CONFIG)
    scans = batches(targets, seconds, ns=service.namespace)
    return [r for scan in scans for r in scan], service


def _run(records: list, service: ServiceConfig, *, batch: int, more: bool) -> tuple[Pipeline, Consumer]:
    pipe = Pipeline(Tracker(service.tracker), wire.Codec(service.namespace))
    consumer = Consumer()
    for i in range(0, len(records), batch):
        chunk = records[i:i + batch]
        out = pipe.ingest(chunk, more=more and i + batch < len(records))
        consumer.take(out.result)
        c = pipe.counts()
        assert c.received == c.applied + c.inputs + c.truth + sum(c.refused.values()), "counts do not add up"
        assert c.received + pipe.holding == min(i + batch, len(records))
    assert pipe.holding == 0
    return pipe, consumer


def test_held_scans_give_the_same_tracks_without_rescans() -> None:
    records, service = _records(30, 6.0)
    whole, whole_res = _run(records, service, batch=len(records), more=False)
    cut, cut_res = _run(records, service, batch=53, more=False)
    held, held_res = _run(records, service, batch=53, more=True)
    assert held_res.snapshot() == cut_res.snapshot() == whole_res.snapshot()
    assert held_res.events == cut_res.events == whole_res.events
    assert track_snapshot(held.tracker) == track_snapshot(cut.tracker) == track_snapshot(whole.tracker)
    assert data_counts(held.tracker) == data_counts(cut.tracker) == data_counts(whole.tracker)
    rescans = {k: p.tracker.arrival_counts["rescans"] for k, p in (("cut", cut), ("held", held), ("whole", whole))}
    assert rescans["cut"] > 20, rescans  # the batch size cuts scans: the test shows something
    assert rescans["held"] == rescans["whole"] == 0, rescans


def test_a_batch_of_one_scan_waits_whole() -> None:
    records, service = _records(5, 1.0)
    pipe = Pipeline(Tracker(service.tracker), wire.Codec(service.namespace))
    meas = [r for r in records if "/meas/" in r[1]]
    first = pipe.ingest(meas[:1], more=True)
    assert pipe.holding == 1 and not first.result.estimates and pipe.counts().received == 0
    out = pipe.ingest([], more=False)
    assert pipe.holding == 0 and pipe.counts().received == 1 and out.result.estimates


def _blast_the_mix(tmp_path, observe, **intake: int) -> list:
    """10 s of the mix, as fast as it goes, at a live service with the given [intake] settings;
    `observe(svc, batch, more, decoded, step)` wraps each batch on the loop's thread. Returns
    what observe returned for each batch, once the final counts show everything received, none
    queued, every measurement applied, a duplicate or refused."""
    import msgspec

    from publishers.publish import publish
    from publishers.stream import build_stream
    from tests.service.harness import client, running_service, scenario_config

    spec, cfg = scenario_config("mix")
    spec = msgspec.structs.replace(spec, duration_s=10.0)
    cfg = msgspec.structs.replace(cfg, intake=msgspec.structs.replace(cfg.intake, **intake))
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    seen: list = []
    with running_service(cfg, tmp_path) as (svc, endpoint):
        step = svc._step

        def probe(batch, *, more=False, decoded=None, **other):  # on the loop's thread
            # keywords _step has beyond these go through as they came (observe passes more and decoded)
            seen.append(observe(svc, batch, more, decoded, functools.partial(step, **other)))

        svc._step = probe  # type: ignore[method-assign]
        pub = client(endpoint)
        try:
            publish(pub, samples, speed=0.0, match_timeout_s=5.0)
        finally:
            pub.close()
        assert svc.wait_idle(timeout_s=60.0)
        final = svc.status_dict()["counts"]
    meas = sum(1 for s in samples if "/meas/" in s.key)
    assert final["queued"] == 0 and final["received"] == len(samples)
    assert final["applied"] + final["duplicates"] + sum(final["refused"].values()) == meas
    return seen


def test_the_service_holds_a_cut_scan_only_with_a_backlog_and_its_counts_add_up(tmp_path) -> None:
    """The live service with batches of 40 samples (intake.batch_max) fed the mix as fast as it
    goes: full batches with a backlog behind them pass `more`, the counts in the status add up
    after every batch (held measurements count as queued), and everything is applied in the end."""

    def after_each(svc, batch, more, decoded, step):
        step(batch, more=more, decoded=decoded)
        return more, svc.pipeline.holding, svc.status_dict()["counts"]

    seen = _blast_the_mix(tmp_path, after_each, batch_max=40, late_batch_max=40)
    assert any(more and held for more, held, _ in seen), "no batch held a scan: no backlog formed"
    for _, _, c in seen:
        assert c["received"] == c["applied"] + c["truth"] + c["duplicates"] + sum(c["refused"].values()) + c["queued"]


def test_a_full_batch_with_late_data_grows_to_late_batch_max(tmp_path) -> None:
    """The live service with batch_max 40 and late_batch_max 200, fed the mix (its sensors'
    latencies deliver measurements after later scans) as fast as it goes: a full batch holding
    a measurement of a scan before the tracker's newest, with a backlog behind it, is grown up
    to 200 samples; no batch without late data is; everything is applied."""

    def before_each(svc, batch, more, decoded, step):
        late = decoded is not None and svc._holds_late(decoded)
        step(batch, more=more, decoded=decoded)
        return len(batch), late

    seen = _blast_the_mix(tmp_path, before_each, batch_max=40, late_batch_max=200)
    grown = [n for n, late in seen if n > 40]
    assert grown and max(grown) <= 200 and all(late for n, late in seen if n > 40), seen
