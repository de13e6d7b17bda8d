"""The recording reads back the same as before the sink's batching was restructured: the same
entities, the same number of rows in each, the same rows (tests/io/data/recording_reference.json,
written by `python -m tests.io.recording_digest` with the sink of commit e05ae9d), for seeded runs
of three reference scenarios: mix (IMM, radar + camera, clutter, late data: replays and
retractions), helix3d (3-D: ellipsoids) and cv1d_a (1-D)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.io.recording_digest import SCENARIOS, digest, record

REFERENCE = json.loads((Path(__file__).parent / "data" / "recording_reference.json").read_text())


@pytest.mark.parametrize("name", sorted(SCENARIOS), ids=sorted(SCENARIOS))
def test_recording_reads_back_as_before(name: str, tmp_path: Path) -> None:
    path = tmp_path / f"{name}.rrd"
    record(name, path, duration_s=SCENARIOS[name])
    got, want = digest(path), REFERENCE[name]
    assert sorted(got) == sorted(want), f"entities differ: missing {sorted(set(want) - set(got))}, " \
                                        f"new {sorted(set(got) - set(want))}"
    rows = {e: (got[e]["static"], got[e]["rows"]) for e in got if (got[e]["static"], got[e]["rows"]) !=
            (want[e]["static"], want[e]["rows"])}
    assert not rows, f"rows (static, not) differ: {rows} (reference: {[want[e]['rows'] for e in rows]})"
    content = sorted(e for e in got if got[e]["hash"] != want[e]["hash"])
    assert not content, f"the rows of {content} differ"
