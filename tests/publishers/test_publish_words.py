"""What fusion-publish and fusion demo say they sent: measurements, control inputs and truth, each
said when there were any (a cv1d_d demo said "sent 100 measurements and 100 truth samples" and
nothing of its 100 control inputs; fusion-publish said "published 100 input and ...")."""

from __future__ import annotations

from pathlib import Path

from publishers.publish import sent_words


def test_sent_words() -> None:
    assert sent_words({"meas": 6496, "truth": 3600}) == "6496 measurements and 3600 truth samples"
    assert sent_words({"truth": 100, "input": 100, "meas": 100}) == \
        "100 measurements, 100 control inputs and 100 truth samples"
    assert sent_words({"meas": 5}) == "5 measurements"
    assert sent_words({"meas": 5}, always=("meas", "truth")) == "5 measurements and 0 truth samples"
    assert sent_words({}) == "nothing"
    assert sent_words({"meas": 2, "other": 3}) == "2 measurements and 3 other"


def test_the_demo_says_the_control_inputs_it_sent(tmp_path: Path) -> None:
    from publishers.demo import demo_report, run_demo

    r = run_demo(scenario="cv1d_d", out=tmp_path / "cv1d_d.rrd", speed=0.0)
    assert r.published == {"meas": 100, "input": 100, "truth": 100}
    report = demo_report(r)
    assert "  sent       100 measurements, 100 control inputs and 100 truth samples\n" in report, report
    assert "received 100 measurements and 100 control inputs: 100 applied" in report
