"""The words the CLI prints match the numbers (in-process: the wording functions alone)."""

from __future__ import annotations

import msgspec

from fusion import messages as m
from fusion.cli.report import counts_line, flat_counts, format_status, format_tracks
from fusion.tracking.detection import Reason
from fusion.tracking.results import Counts

BASE = {"received": 838, "applied": 530, "duplicates": 4, "refused": {"invalid": 4}, "queued": 0, "truth": 300,
        "late_applied": 8, "replays": 1, "published": 389}
LINE = ("received 538 measurements: 530 applied, 4 duplicates dropped, 4 refused (invalid 4); 8 late ones folded "
        "in by 1 replay; published 389 estimate messages (revisions included)")


def test_counts_line_says_measurements_not_truth_samples() -> None:
    """received counts every sample; the line speaks of the measurements among them."""
    assert counts_line(BASE) == LINE


def test_flat_pipeline_counts() -> None:
    c = Counts(received=838, truth=300, applied=530, late_applied=8, replays=1,
               refused={Reason.DUPLICATE: 4, Reason.INVALID: 4, Reason.FUTURE: 0})
    assert counts_line(flat_counts(c, published=389)) == LINE


def test_queued_and_no_late() -> None:
    c = dict(BASE, received=840, queued=2, late_applied=0, replays=0, refused={})
    assert counts_line(c) == ("received 540 measurements: 530 applied, 4 duplicates dropped, 0 refused, 2 not yet "
                              "processed; published 389 estimate messages (revisions included)")


def test_control_inputs_are_said_apart() -> None:
    """A stream with control inputs (cv1d_d): the line's parts add up to the measurements."""
    c = Counts(received=300, truth=100, inputs=100, applied=100)
    assert counts_line(flat_counts(c, published=99)) == ("received 100 measurements and 100 control inputs: "
                                                         "100 applied, 0 duplicates dropped, 0 refused; "
                                                         "published 99 estimate messages (revisions included)")


def _estimate(track_id: int, x: float) -> m.Estimate:
    return m.Estimate(track_id=track_id, t_ns=2_500_000_000, sensor_id="cam1", seq=3, state=[x, 1.0, 2.0, -1.0],
                      cov=[4.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 5.0, 0, 0, 0, 0, 1.0], layout=["x", "vx", "y", "vy"],
                      model="cv", status="confirmed", revision=0, nis=1.5)


def test_tracks_table() -> None:
    text = format_tracks(m.Snapshot(estimates=[_estimate(7, 10.0), _estimate(3, -5.0)]), "demo")
    lines = text.splitlines()
    assert lines[0] == "namespace 'demo': 2 confirmed tracks (model cv, latest estimate of each)"
    assert lines[1].split() == ["track", "time", "x", "vx", "y", "vy", "pos", "std", "sensor", "NIS"]
    from fusion.io.labels import short_id

    assert lines[2].split() == [short_id(3), "2.500", "s", "-5.00", "1.00", "2.00", "-1.00", "3.00", "cam1", "1.50"]
    assert format_tracks(m.Snapshot(estimates=[]), "x") == "namespace 'x': no confirmed tracks right now"


def test_status_text() -> None:
    st = m.ServiceStatus(uptime_s=125.0, counts=m.Counts(received=10, applied=9, duplicates=1, refused={}, queued=0,
                                                          replays=0, late_applied=0, published=7, truth=0),
                         tracks={"confirmed": 2, "tentative": 1}, latency={}, recording="r.rrd",
                         recording_bytes=2_000_000, queue_depth=0)
    text = format_status(st, "demo")
    assert text.splitlines()[0] == "fusion service on namespace 'demo', up 2 min 5 s"
    assert "received 10 measurements: 9 applied, 1 duplicates dropped, 0 refused; published 7 estimate messages" in text
    assert "2 confirmed, 1 tentative" in text and "r.rrd (2.0 MB)" in text
    behind = format_status(msgspec.structs.replace(st, recording_queue=1234), "demo")
    assert "r.rrd (2.0 MB; 1234 rows still to write)" in behind


def test_status_text_explains_a_negative_latency() -> None:
    """Latency is arrival - sensor time: below 0 after `fusion-publish --speed max`, whose sensor
    times run ahead of the wall clock (seen by hand: "pos: mean -5035.8 ms"); said, not left to
    look like a bug. A positive one is shown as before."""
    lat = {"pos": m.LatencyStats(count=100, mean_ms=-5035.8, p50_ms=-5035.8, p99_ms=-184.9, max_ms=-85.9),
           "cam1": m.LatencyStats(count=10, mean_ms=3.5, p50_ms=3.0, p99_ms=9.0, max_ms=9.5)}
    st = m.ServiceStatus(uptime_s=5.0, counts=m.Counts(received=110, applied=110, duplicates=0, refused={}, queued=0,
                                                        replays=0, late_applied=0, published=100, truth=0),
                         tracks={}, latency=lat, recording=None, recording_bytes=0, queue_depth=0)
    text = format_status(st, "demo")
    assert ("  latency    pos: mean -5035.8 ms, p50 -5035.8, p99 -184.9, max -85.9 ms over 100 measurements (below 0: "
            "its times are ahead of when they arrive; a publisher faster than real time, or a clock ahead of this "
            "machine's)") in text
    assert "  latency    cam1: mean 3.5 ms, p50 3.0, p99 9.0, max 9.5 ms over 10 measurements\n" in text + "\n"


def test_status_text_says_what_failed_and_what_was_resumed() -> None:
    st = m.ServiceStatus(uptime_s=5.0, counts=m.Counts(received=0, applied=0, duplicates=0, refused={}, queued=0,
                                                        replays=0, late_applied=0, published=0, truth=0),
                         tracks={}, latency={}, recording=None, recording_bytes=0, queue_depth=0,
                         recording_error="recordings: not a folder",
                         checkpoint=m.CheckpointStatus(path="c.ckpt", resumed_tracks=3, resumed_age_s=42.0, written=2,
                                                       last_written_age_s=1.5))
    text = format_status(st, "demo")
    assert "recording  FAILED: recordings: not a folder (tracking and publishing go on)" in text
    assert "checkpoint c.ckpt: resumed 3 tracks from a checkpoint 42.0 s old; 2 written; last written 1.5 s ago" \
        in text
    fresh = msgspec.structs.replace(st, recording_error=None, checkpoint=m.CheckpointStatus(
        path="c.ckpt", resumed_tracks=0, refused="damaged (crc)", written=0, error="disk full"))
    text = format_status(fresh, "demo")
    assert "FAILED" not in text.split("checkpoint")[0]
    assert "started with no checkpoint; one found at start was refused: damaged (crc); 0 written; the last write " \
           "FAILED: disk full" in text


def test_a_recording_that_cannot_be_written_is_a_file_error_not_an_internal_one() -> None:
    from fusion.cli.runner import Exit, classify

    e = classify(RuntimeError("Failed to create file: No space left on device (os error 28), path: /full/x.rrd"))
    assert e.code == Exit.FILE
    assert str(e).startswith("/full/x.rrd: cannot write the recording (Failed to create file: No space left on device")
    assert classify(RuntimeError("something else")).code == Exit.INTERNAL
