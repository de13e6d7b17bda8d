"""Publisher faults against a real `fusion serve` (issue #13): a publisher killed mid-stream, and
one in a crash loop (started and SIGKILLed again and again, each run a new process with a new
epoch and seq counting from 0 again). The service keeps serving, every run's measurements are
taken (not refused as duplicates of an earlier run's seq), its status tells the runs apart, and
the counts add up throughout."""

from __future__ import annotations

import signal
import time
from pathlib import Path

from fusion import messages as m
from tests.cli.helpers import SERVICE_TOML, start, stop
from tests.service.test_crash import Served, _wait


def _adds_up(c: m.Counts) -> bool:
    return c.received == c.applied + c.inputs + c.truth + c.duplicates + sum(c.refused.values()) + c.queued


def test_a_publisher_in_a_crash_loop_costs_only_its_lost_samples(tmp_path: Path) -> None:
    sv = Served(SERVICE_TOML, tmp_path / "rec", tmp_path)
    try:
        before = sv.status().counts.applied
        runs = 4
        for k in range(runs):  # each run killed mid-stream, once it has delivered something
            pub = start("fusion-publish", "-s", "mix", "-e", sv.ep, "--speed", "1", "-q", cwd=tmp_path)
            try:
                _wait(lambda b=before: sv.status().counts.applied > b + 20, 30.0, f"run {k}'s measurements")
            finally:
                pub.send_signal(signal.SIGKILL)
                pub.wait(timeout=10)
                for f in (pub.stdout, pub.stderr):
                    if f is not None:
                        f.close()
            st = sv.status()
            assert _adds_up(st.counts), st.counts
            assert st.counts.applied > before, f"run {k}: nothing of it was applied"
            before = st.counts.applied
        last = start("fusion-publish", "-s", "mix", "-e", sv.ep, "--speed", "1", "--duration", "4", "-q", cwd=tmp_path)
        out, err = last.communicate(timeout=60)
        assert last.returncode == 0, err
        assert "published" in out
        _wait(lambda: sv.status().counts.queued == 0, 20.0, "the service to catch up")
        time.sleep(0.3)  # the status answer is refreshed between batches
        st = sv.status()
        c = st.counts
        assert _adds_up(c), c
        assert c.applied > before
        # the mix's own simulated duplicates are the only ones: no run's seq 0.. was taken for an
        # earlier run's (a restart gives a new epoch)
        assert c.duplicates < 0.02 * c.applied, c
        gaps = st.gaps["radar1"]
        assert gaps.epochs == runs + 1 and gaps.restarts == runs, gaps
        assert st.tracks.get("confirmed", 0) >= 1, st.tracks
        assert sv.proc.poll() is None, "the service died"
    finally:
        stop(sv.proc)
        sv.close()
    assert sv.proc.returncode == 0
