"""Recording faults and limits: the .fstream rotates with the .rrd (and by size), retention keeps
the folder bounded, and a recording that fails (disk full, folder gone) stops tracking nothing."""

from __future__ import annotations

import shutil
from pathlib import Path

import msgspec
import pytest

from fusion.config import RecordingConfig
from fusion.io.outputs import Outputs
from fusion.io.stream_rotation import Retention, RotatingStream
from fusion.io.streamfile import StreamReader
from publishers.publish import publish
from publishers.stream import build_stream
from tests.service.harness import EstimateCollector, client, scenario_config
from tests.service.reliability_helpers import service_thread, settled_status


def rec(i: int) -> tuple[int, str, bytes]:
    return i, "fusion/demo/meas/cam1", bytes([i % 256]) * 100


def test_the_stream_follows_the_recording_and_rotates_by_size(tmp_path: Path) -> None:
    current = [tmp_path / "f-0000.rrd"]
    s = RotatingStream(tmp_path / "f-0000.fstream", namespace="demo", rotate_bytes=10**9, follow=lambda: current[0])
    for i in range(10):
        s.write(*rec(i))
    current[0] = tmp_path / "f-0001.rrd"
    for i in range(10, 25):
        s.write(*rec(i))
    s.close()
    assert s.files == [tmp_path / "f-0000.fstream", tmp_path / "f-0001.fstream"]
    assert [r[0] for r in StreamReader(s.files[0])] == list(range(10))
    assert [r[0] for r in StreamReader(s.files[1])] == list(range(10, 25))

    b = RotatingStream(tmp_path / "g.fstream", namespace="demo", rotate_bytes=1000)
    for i in range(50):
        b.write(*rec(i))
    b.close()
    assert len(b.files) == 7 and b.files[1].name == "g-1.fstream"
    assert [r[0] for f in b.files for r in StreamReader(f)] == list(range(50)), "a record lost at a boundary"


class _MovingRecording:
    """A recording that moves to its next file when closed or on `move()` (as RotatingSink does
    at a step after the stream took the batch's records)."""

    def __init__(self, directory: Path) -> None:
        self.directory, self.n = directory, 0

    @property
    def path(self) -> Path:
        return self.directory / f"f-{self.n:04d}.rrd"

    def move(self) -> None:
        self.n += 1

    def close(self) -> None:
        self.move()


def test_every_recording_file_gets_its_stream_file_also_without_records(tmp_path: Path) -> None:
    """The recording moves to a new file at the batch's steps, after the stream wrote the batch:
    between batches (maybe_sweep) and at close the stream follows it, so no .rrd is without its
    .fstream (before, the last file of a run had none)."""
    sink = _MovingRecording(tmp_path)
    stream = RotatingStream(tmp_path / "f-0000.fstream", namespace="demo", rotate_bytes=10**9,
                            follow=lambda: sink.path)
    out = Outputs(sink, stream, None, None)  # type: ignore[arg-type]
    stream.write_many([rec(i) for i in range(5)])
    sink.move()  # the batch's steps moved the recording on
    out.maybe_sweep()  # the loop between batches, with no record to write
    out.close()
    assert [p.name for p in stream.files] == ["f-0000.fstream", "f-0001.fstream", "f-0002.fstream"]
    assert [r[0] for r in StreamReader(stream.files[0])] == list(range(5))
    assert all(list(StreamReader(p)) == [] for p in stream.files[1:]), "the later ones are complete, empty files"


@pytest.mark.parametrize("batch", [1, 3, 7, 50], ids=lambda b: f"batch{b}")
def test_a_batch_write_rotates_where_record_writes_do(tmp_path: Path, batch: int) -> None:
    """write_many splits a batch at the size boundaries one write per record would: the same
    files, the same records in each."""
    one = RotatingStream(tmp_path / "one.fstream", namespace="demo", rotate_bytes=1000)
    for i in range(50):
        one.write(*rec(i))
    one.close()
    many = RotatingStream(tmp_path / "many.fstream", namespace="demo", rotate_bytes=1000)
    recs = [rec(i) for i in range(50)]
    for k in range(0, 50, batch):
        many.write_many(recs[k:k + batch])
    many.close()
    assert many.records == 50 and many.lost == 0
    assert [[r for r in StreamReader(f)] for f in many.files] == [[r for r in StreamReader(f)] for f in one.files]


def test_a_batch_that_cannot_be_written_is_counted_lost(tmp_path: Path) -> None:
    d = tmp_path / "rec"
    current = [d / "f-0000.rrd"]
    s = RotatingStream(d / "f-0000.fstream", namespace="demo", rotate_bytes=10**9, follow=lambda: current[0])
    s.write_many([rec(i) for i in range(5)])
    shutil.rmtree(d)
    d.write_text("now a file, not a folder")
    current[0] = d / "f-0001.rrd"
    s.write_many([rec(i) for i in range(5, 20)])
    s.close()
    assert s.error is not None and s.records == 5 and s.lost == 15


def test_a_stream_whose_folder_is_gone_stops_and_counts_what_it_lost(tmp_path: Path) -> None:
    d = tmp_path / "rec"
    current = [d / "f-0000.rrd"]
    s = RotatingStream(d / "f-0000.fstream", namespace="demo", rotate_bytes=10**9, follow=lambda: current[0])
    for i in range(5):
        s.write(*rec(i))
    shutil.rmtree(d)
    d.write_text("now a file, not a folder")  # even root cannot create files under it
    current[0] = d / "f-0001.rrd"
    for i in range(5, 20):
        s.write(*rec(i))  # never raises
    s.close()
    assert s.error is not None and "f-0001.fstream" in s.error
    assert s.records == 5 and s.lost == 15


def test_retention_by_count_and_bytes_never_deletes_open_files(tmp_path: Path) -> None:
    for i in range(6):
        (tmp_path / f"fusion-20260101T00000{i}-0000.rrd").write_bytes(b"r" * 1000)
        (tmp_path / f"fusion-20260101T00000{i}-0000.fstream").write_bytes(b"s" * 500)
    (tmp_path / "other-20260101T000000-0000.rrd").write_bytes(b"x")  # another prefix: not ours
    newest = (tmp_path / "fusion-20260101T000005-0000.rrd", tmp_path / "fusion-20260101T000005-0000.fstream")
    gone = Retention(tmp_path, prefix="fusion", keep_files=3, keep_bytes=0).sweep(newest)
    assert len(gone) == 6 and sorted(p.name for p in tmp_path.glob("fusion-*.rrd"))[0].startswith(
        "fusion-20260101T000003")
    gone = Retention(tmp_path, prefix="fusion", keep_files=0, keep_bytes=2000).sweep(newest)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*(p.name for p in newest),
                                                                 "other-20260101T000000-0000.rrd"])
    assert Retention(tmp_path, prefix="fusion", keep_files=0, keep_bytes=1).sweep(newest) == []


def test_a_recordings_folder_gone_stops_the_recording_not_the_tracking(tmp_path: Path) -> None:
    """Mid-run, the recordings folder becomes a file: at the next rotation the .rrd cannot be
    created (nor the checkpoint written). Every measurement is still applied and its estimates published;
    the status says the recording failed and why."""
    spec, cfg = scenario_config("radar2d")
    spec = msgspec.structs.replace(spec, duration_s=3.0)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    d = tmp_path / "rec"
    rc = RecordingConfig(prefix="r", rotate_s=0.3)
    with service_thread(msgspec.structs.replace(cfg, recording=rc), recording_dir=d) as (svc, endpoint, _):
        s = client(endpoint)
        try:
            col = EstimateCollector(s, cfg.namespace)
            publish(s, samples[:10], speed=1.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=30.0)
            shutil.rmtree(d)
            d.write_text("not a folder any more")
            publish(s, samples[10:], speed=1.0, match_timeout_s=5.0)
            st = settled_status(svc, s, cfg.namespace)
            got = col.snapshot()
        finally:
            s.close()
    n_meas = sum(1 for x in samples if "/meas/" in x.key)
    assert st.counts.applied == n_meas and st.tracks == {"confirmed": 1}
    assert len(got) == st.counts.published > n_meas // 2
    assert st.recording_error is not None
    assert ".rrd failed: FileExistsError" in st.recording_error
    assert svc.checkpoints is not None and "cannot write the checkpoint" in (svc.checkpoints.error or ""), \
        "the shutdown checkpoint went to the same folder: its failure is reported, not raised"


def test_the_service_rotates_both_files_and_keeps_the_newest(tmp_path: Path) -> None:
    spec, cfg = scenario_config("radar2d")
    spec = msgspec.structs.replace(spec, duration_s=4.0)
    samples, _ = build_stream(spec, namespace=cfg.namespace)
    rc = RecordingConfig(prefix="r", rotate_s=0.5, keep_files=2, keep_mb=0.0)
    with service_thread(msgspec.structs.replace(cfg, recording=rc), recording_dir=tmp_path) as (svc, endpoint, _):
        s = client(endpoint)
        try:
            publish(s, samples, speed=1.0, match_timeout_s=5.0)
            assert svc.wait_idle(timeout_s=30.0)
        finally:
            s.close()
    rrds = sorted(tmp_path.glob("r-*.rrd"))
    streams = sorted(tmp_path.glob("r-*.fstream"))
    assert svc.stream is not None and len(svc.stream.files) >= 4, "the stream did not rotate with the recording"
    assert len(rrds) == 2 and [p.stem for p in streams] == [p.stem for p in rrds]
    kept = [r for p in streams for r in StreamReader(p)]
    assert kept and [r[0] for r in kept] == sorted(r[0] for r in kept)
    assert svc.status_dict()["recording_error"] is None


def test_an_unwritable_stream_is_an_error_not_an_exception(tmp_path: Path) -> None:
    blocker = tmp_path / "blocked"
    blocker.write_text("a file")
    s = RotatingStream(blocker / "x.fstream", namespace="demo", rotate_bytes=10**6)
    s.write(*rec(1))
    s.close()
    assert s.error is not None and s.lost == 1 and s.files == []
