"""fusion.io.memory: the resident memory of a process, read from /proc."""

from __future__ import annotations

import os

import numpy as np
import pytest

from fusion.io.memory import parse_status, process_memory


def test_own_memory_adds_up_and_sees_an_allocation() -> None:
    before = process_memory()
    assert before.rss_mb > 0 and before.file_mb > 0
    assert before.rss_mb == pytest.approx(before.anon_mb + before.file_mb + before.shmem_mb, abs=0.01)
    block = np.ones(64 * 2**20 // 8)  # 64 MB, touched
    after = process_memory(os.getpid())
    assert after.anon_mb - before.anon_mb == pytest.approx(64, abs=8)
    assert after.peak_mb >= after.rss_mb
    del block


def test_status_text_parsed_and_incomplete_refused() -> None:
    text = "Name:\tx\nVmHWM:\t  2048 kB\nVmRSS:\t  1024 kB\nRssAnon:\t 512 kB\nRssFile:\t 384 kB\nRssShmem:\t 128 kB\n"
    m = parse_status(text)
    assert (m.rss_mb, m.anon_mb, m.file_mb, m.shmem_mb, m.peak_mb) == (1.0, 0.5, 0.375, 0.125, 2.0)
    with pytest.raises(ValueError, match="RssAnon"):
        parse_status(text.replace("RssAnon", "Other"))
    with pytest.raises(OSError):
        process_memory(2**31 - 1)
