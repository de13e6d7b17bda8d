"""Per-sensor sequence gaps: opened, filled by late samples, restarts told apart."""

from __future__ import annotations

from fusion import messages as m
from fusion.io.seq_gaps import SeqGaps, peek


def test_gaps_open_and_late_samples_fill_them() -> None:
    g = SeqGaps()
    for q in [0, 1, 2, 5, 6, 3, 9, 9, 2]:
        g.see("cam1", q)
    assert g.status() == {"cam1": {"missing": 3, "filled": 1, "restarts": 0, "highest_seq": 9}}  # 4, 7, 8


def test_a_restarted_publisher_is_a_restart_not_a_gap() -> None:
    g = SeqGaps(restart_window=100)
    for q in range(5000, 5010):
        g.see("radar1", q)
    for q in range(0, 5):
        g.see("radar1", q)
    assert g.status()["radar1"] == {"missing": 0, "filled": 0, "restarts": 1, "highest_seq": 4}


def test_missing_is_bounded() -> None:
    g = SeqGaps(max_missing=10)
    g.see("a", 0)
    g.see("a", 10**12)
    assert g.status()["a"]["missing"] == 10


def test_peek_reads_sensor_and_seq_or_nothing() -> None:
    msg = m.Measurement(sensor_id="cam1", t_ns=5, seq=42, data=m.Cartesian(pos_m=[1.0]))
    assert peek(m.encode(msg)) == ("cam1", 42)
    assert peek(b"\xc1junk") is None and peek(m.encode(m.Truth(target_id="x", t_ns=1, state=[0.0], layout=["x"]))) \
        is None
