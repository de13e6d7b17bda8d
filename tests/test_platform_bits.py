"""tests.platform_bits: a pinned value is the one of this machine's floating-point platform, and a
machine with none skips with the reason instead of failing on other last bits."""

from __future__ import annotations

import pytest

from tests import platform_bits


def test_the_fingerprint_is_stable_and_names_a_pinned_platform_here() -> None:
    fp = platform_bits.fingerprint.__wrapped__()  # computed again, not the cached value
    assert fp == platform_bits.fingerprint()
    assert len(fp) == 16 and int(fp, 16) >= 0


def test_pinned_gives_the_value_of_the_machine_s_platform(monkeypatch: pytest.MonkeyPatch) -> None:
    fp = next(k for k, v in platform_bits.PLATFORMS.items() if v == "x86-64-avx2")
    monkeypatch.setattr(platform_bits, "fingerprint", lambda: fp)
    assert platform_bits.pinned({"x86-64-avx512": 1, "x86-64-avx2": 2}, "x") == 2


@pytest.mark.parametrize("fp", ["0123456789abcdef", "avx2-not-pinned"])
def test_an_unpinned_machine_skips_saying_why(monkeypatch: pytest.MonkeyPatch, fp: str) -> None:
    if fp == "avx2-not-pinned":  # a known platform the table has no value for
        fp = next(k for k, v in platform_bits.PLATFORMS.items() if v == "x86-64-avx2")
    monkeypatch.setattr(platform_bits, "fingerprint", lambda: fp)
    with pytest.raises(pytest.skip.Exception, match=f"the digest is pinned bit for bit on .*{fp}"):
        platform_bits.pinned({"x86-64-avx512": 1}, "the digest")
