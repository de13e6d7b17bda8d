"""Stream files: every complete frame survives a crash at any byte (a frame per record, or per
batch); version 1 files (a frame per record) still read; .jsonl input; the recorder."""

from __future__ import annotations

import json
import logging
import struct
import time
import zlib
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from fusion import messages as m
from fusion.io.recorder import Recorder
from fusion.io.streamfile import StreamFormatError, StreamReader, StreamWriter, read_records
from publishers.publish import publish
from publishers.spec import load_scenario_file, scenario_path
from publishers.stream import build_stream


def _records(n: int) -> list[tuple[int, str, bytes]]:
    out = []
    for i in range(n):
        msg = m.Measurement(sensor_id="c", t_ns=i, seq=i, data=m.Cartesian(pos_m=[i, 2.0 * i], std_m=[1.0, 1.0]))
        out.append((1000 + i, "fusion/t/meas/c", m.encode(msg)))
    return out


def test_round_trip(tmp_path: Path) -> None:
    recs = _records(50)
    with StreamWriter(tmp_path / "s.fstream", namespace="t") as w:
        for r in recs:
            w.write(*r)
    r = StreamReader(tmp_path / "s.fstream")
    assert r.meta["namespace"] == "t"
    assert list(r) == recs
    assert not r.truncated


def test_a_batch_is_one_frame_and_reads_back_as_its_records(tmp_path: Path) -> None:
    recs = _records(30)
    with StreamWriter(tmp_path / "one.fstream", namespace="t") as w:
        for r in recs:
            w.write(*r)
    with StreamWriter(tmp_path / "many.fstream", namespace="t") as w:
        first, none, n = w.write_many(recs[:10]), w.write_many([]), w.write_many(recs[10:])
        assert w.records == 30 and none == 0
    assert list(StreamReader(tmp_path / "many.fstream")) == list(StreamReader(tmp_path / "one.fstream")) == recs
    many = (tmp_path / "many.fstream").read_bytes()
    assert 0 < first + n < len(many) < (tmp_path / "one.fstream").stat().st_size
    body = many[-n + 8:]
    assert struct.unpack("<II", many[-n:-n + 8]) == (n - 8, zlib.crc32(body))
    assert msgspec.msgpack.decode(body) == [list(r) for r in recs[10:]], "the last write is one frame of its records"


def test_numpy_integers_and_byte_views_are_written_plain(tmp_path: Path) -> None:
    recs = _records(3)
    with StreamWriter(tmp_path / "s.fstream", namespace="t") as w:
        w.write_many([(np.int64(a), k, memoryview(p)) for a, k, p in recs])
    assert list(StreamReader(tmp_path / "s.fstream")) == recs


def test_a_cut_batch_loses_that_batch_only(tmp_path: Path) -> None:
    recs = _records(40)
    full = tmp_path / "s.fstream"
    with StreamWriter(full, namespace="t") as w:
        w.write_many(recs[:25])
        end = full.stat().st_size
        w.write_many(recs[25:])
    data = full.read_bytes()
    cut = tmp_path / "cut.fstream"
    for size in (end, end + 1, end + 8, len(data) - 1):
        cut.write_bytes(data[:size])
        reader = StreamReader(cut)
        assert list(reader) == recs[:25] and reader.truncated == (size != end), size


def _v1_file(path: Path, recs: list[tuple[int, str, bytes]]) -> None:
    """A stream file as version 1 wrote it: a frame per record, its body one [arrival_ns, key, payload]."""
    blob = json.dumps({"namespace": "t", "created_ns": 0}).encode()
    out = [struct.pack("<8sHI", b"FUSIONST", 1, len(blob)), blob]
    for r in recs:
        body = msgspec.msgpack.encode(r)
        out.append(struct.pack("<II", len(body), zlib.crc32(body)) + body)
    path.write_bytes(b"".join(out))


def test_version_1_files_still_read(tmp_path: Path) -> None:
    recs = _records(12)
    p = tmp_path / "old.fstream"
    _v1_file(p, recs)
    r = StreamReader(p)
    assert r.version == 1 and r.meta["namespace"] == "t"
    assert list(r) == recs and not r.truncated
    p.write_bytes(p.read_bytes()[:-5])  # a cut last frame, as before
    r = StreamReader(p)
    assert list(r) == recs[:-1] and r.truncated
    got, meta = read_records(p)
    assert list(got) == recs[:-1] and meta["namespace"] == "t"


def test_an_unknown_version_is_refused_with_the_versions_known(tmp_path: Path) -> None:
    p = tmp_path / "new.fstream"
    p.write_bytes(struct.pack("<8sHI", b"FUSIONST", 9, 2) + b"{}")
    with pytest.raises(StreamFormatError, match="version 9, this reader knows 1, 2"):
        StreamReader(p)


def test_cut_at_every_byte_of_the_last_frames(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    recs = _records(20)
    full = tmp_path / "s.fstream"
    ends = []
    with StreamWriter(full, namespace="t") as w:
        for r in recs:
            w.write(*r)
            ends.append(full.stat().st_size)
    data = full.read_bytes()
    cut = tmp_path / "cut.fstream"
    for size in range(ends[14] - 3, len(data) + 1):
        cut.write_bytes(data[:size])
        complete = sum(1 for e in ends if e <= size)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="fusion.stream"):
            reader = StreamReader(cut)
            got = list(reader)
        caught = [r for r in caplog.records if "partial or corrupt last frame" in r.getMessage()]
        assert got == recs[:complete], size
        partial = size not in ends
        assert reader.truncated == partial, size
        assert bool(caught) == partial, size


def test_bad_header(tmp_path: Path) -> None:
    p = tmp_path / "x.fstream"
    p.write_bytes(b"NOTAFUSIONFILE..")
    with pytest.raises(StreamFormatError, match="not a fusion stream"):
        StreamReader(p)


def test_jsonl(tmp_path: Path) -> None:
    recs = _records(3)
    p = tmp_path / "m.jsonl"
    p.write_bytes(b"\n".join(m.encode_json(m.decode_measurement(r[2])) for r in recs) + b"\n\n")
    got, _meta = read_records(p, namespace="t")
    assert [(k, m.decode_measurement(pl)) for _, k, pl in got] == [(k, m.decode_measurement(pl)) for _, k, pl in recs]
    bad = tmp_path / "bad.jsonl"
    bad.write_bytes(b'{"type":"measurement"}\n')
    with pytest.raises(m.InputError, match=r"bad\.jsonl:1"):
        list(read_records(bad, namespace="t")[0])


def test_jsonl_with_control_inputs_and_truth(tmp_path: Path) -> None:
    """A .jsonl of cv1d_d's messages (measurements, control inputs, truth) reads as the stream
    fusion-publish sends (inputs were refused before); an estimate in it is refused by line."""
    sf = load_scenario_file(scenario_path("cv1d_d"))
    samples, _ = build_stream(sf.scenario, namespace="t")
    assert {s.key.split("/")[2] for s in samples} == {"meas", "input", "truth"}
    p = tmp_path / "cv1d_d.jsonl"
    p.write_bytes(b"".join(m.encode_json(m.decode_any(s.payload)) + b"\n" for s in samples))
    got, _ = read_records(p, namespace="t")
    assert [(k, m.decode_any(pl)) for _, k, pl in got] == [(s.key, m.decode_any(s.payload)) for s in samples]
    est = m.Estimate(track_id=1, t_ns=0, sensor_id="s", seq=0, state=[0.0], cov=[1.0], layout=["x"], model="cv",
                     status="confirmed", revision=0)
    bad = tmp_path / "est.jsonl"
    bad.write_bytes(m.encode_json(est) + b"\n")
    with pytest.raises(m.InputError, match=r"est\.jsonl:1: a stream holds measurements, control inputs and truth"):
        list(read_records(bad, namespace="t")[0])


@pytest.mark.parametrize("name", ["radar2d", "cv1d_d"])  # cv1d_d has control inputs
def test_recorder_over_zenoh(name: str, tmp_path: Path, zenoh_hub: tuple, zenoh_client: Any,
                             caplog: pytest.LogCaptureFixture) -> None:
    hub, _ = zenoh_hub
    sf = load_scenario_file(scenario_path(name))
    samples, _ = build_stream(sf.scenario, namespace="t")
    rec = Recorder(hub, tmp_path / "r.fstream", namespace="t")
    try:
        with caplog.at_level(logging.WARNING, logger="publishers"):
            publish(zenoh_client(), samples, speed=0.0, match_timeout_s=5.0)
        # the recorder is announced as the service is: the publisher did not wait out its timeout
        assert not [r for r in caplog.records if "no subscriber matched" in r.message]
        deadline = time.monotonic() + 5.0
        while rec.records < len(samples) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert rec.missed() == {}
    finally:
        rec.close()
    got = list(StreamReader(tmp_path / "r.fstream"))
    assert sorted(p for _, _, p in got) == sorted(s.payload for s in samples)
