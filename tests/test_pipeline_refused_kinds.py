"""Refused samples are counted by kind: a control input, a truth sample or a sample on a key that
names no kind refused (by the tracker or at the edge, for any reason, duplicates included) is
counted as one (Counts.inputs_refused, truth_refused, other_refused), so the words say how many
measurements were received, not measurements plus refused inputs (a cv1d_d stream replayed with a
configuration without its control source read "received 200 measurements" for 100 measurements
and 100 inputs)."""

from __future__ import annotations

import dataclasses

import msgspec

from fusion import messages as m
from fusion.cli.report import counts_line, flat_counts
from fusion.io import wire
from fusion.pipeline import Pipeline
from fusion.tracking.detection import Reason
from fusion.tracking.results import Counts
from fusion.tracking.tracker import Tracker
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream

NS = "kinds"


def _cv1d_d() -> tuple[list[tuple[int, str, bytes]], Pipeline]:
    sf = load_scenario_file(scenario_path("cv1d_d"))
    samples, _ = build_stream(sf.scenario, namespace=NS)
    return [(s.arrival_ns, s.key, s.payload) for s in samples], Pipeline(Tracker(sf.service.tracker), wire.Codec(NS))


def _adds_up(c: Counts) -> None:
    assert c.received == c.applied + c.inputs + c.truth + sum(c.refused.values())


def test_refused_inputs_and_truth_are_counted_by_kind() -> None:
    records, pipe = _cv1d_d()
    kinds = [wire.Codec(NS).kind(k) for _, k, _ in records]
    n = {k: kinds.count(k) for k in ("meas", "input", "truth")}
    assert n == {"meas": 100, "input": 100, "truth": 100}
    pipe.ingest(records)
    c = pipe.counts()
    assert (c.applied, c.inputs, c.truth, c.inputs_refused, c.truth_refused) == (100, 100, 100, 0, 0)
    assert not {"inputs_refused", "truth_refused", "other_refused"} & c.flat().keys()  # like refused/<reason>: once any

    last = records[-1][0]
    an_input = next(r for r in records if "/input/" in r[1])
    a_truth = next(r for r in records if "/truth/" in r[1])
    a_meas = next(r for r in records if "/meas/" in r[1])
    truth_of = m.decode_any(a_truth[2]).target_id
    bad = [
        (last + 1, an_input[1], an_input[2]),  # the first input again, now before the window (the tracker)
        (last + 2, an_input[1], b"\x00"),  # not an input message, on an input key (the edge)
        (last + 3, m.input_key(NS, "other"), an_input[2]),  # an input of "control" on other's key (the edge)
        (last + 4, m.truth_key(NS, truth_of + "x"), a_truth[2]),  # truth on another target's key (the edge)
        (last + 5, a_meas[1], b"\x00"),  # not a measurement, on a measurement key
        (last + 6, f"fusion/{NS}/weather/w1", a_meas[2]),  # a key of no kind (a wildcard put's, say)
    ]
    pipe.ingest(bad)
    d = pipe.counts()
    _adds_up(d)
    assert (d.received - c.received, d.applied, d.inputs, d.truth) == (6, 100, 100, 100)
    assert (d.inputs_refused, d.truth_refused, d.other_refused) == (3, 1, 1), d
    assert d.refused == {Reason.INVALID: 3, Reason.KEY_MISMATCH: 2, Reason.TOO_LATE: 1}
    assert counts_line(flat_counts(d, published=0)).startswith(
        "received 101 measurements and 103 control inputs: 100 applied, 0 duplicates dropped, 6 refused "
        "(invalid 3, key_mismatch 2, too_late 1); of the duplicates and refused: control inputs 3, truth samples 1, "
        "samples on keys of no kind 1")
    assert (d.flat()["inputs_refused"], d.flat()["truth_refused"], d.flat()["other_refused"]) == (3, 1, 1)


def test_inputs_of_an_unconfigured_source_are_not_said_to_be_measurements() -> None:
    """cv1d_d's stream through a tracker with no control source (mix's): its 100 inputs are refused
    by the tracker as an unknown source and counted as inputs."""
    records, _ = _cv1d_d()
    mix = load_scenario_file(scenario_path("mix")).service
    pipe = Pipeline(Tracker(mix.tracker), wire.Codec(NS))
    pipe.ingest(records)
    c = pipe.counts()
    _adds_up(c)
    assert (c.applied, c.inputs, c.inputs_refused, c.refused) == (0, 0, 100, {Reason.UNKNOWN_SENSOR: 200})
    assert counts_line(flat_counts(c, published=0)) == (
        "received 100 measurements and 100 control inputs: 0 applied, 0 duplicates dropped, 200 refused "
        "(unknown_sensor 200); of the duplicates and refused: control inputs 100; published 0 estimate messages "
        "(revisions included)")


def test_a_status_from_before_the_kinds_were_counted_reads_as_before() -> None:
    """A status message without the new fields (a service of before) decodes with 0 for them."""
    st = m.Counts(received=3, applied=1, duplicates=1, refused={"invalid": 1}, queued=0, replays=0, late_applied=0,
                  published=1, truth=0)
    new = ("inputs_refused", "truth_refused", "other_refused")
    old = {k: v for k, v in msgspec.to_builtins(st).items() if k not in new}
    back = msgspec.convert(old, m.Counts)
    assert (back.inputs_refused, back.truth_refused, back.other_refused) == (0, 0, 0)
    assert dataclasses.asdict(Counts()).keys() >= set(new)
