"""bench.compiled_bits measures what compiled code reproduces bit for bit; the IMM's mixture kernel
(fusion.core.compiled_imm.mixture_many) relies on two of its answers: numba's LAPACK solve gives
numpy's batched solve's bits, and numpy's einsum sums a short axis in two lanes. If a numpy,
scipy or numba upgrade changes either, this says which (the pinned scan digests would only say
that something changed)."""

from __future__ import annotations

from bench.compiled_bits import measure
from tests.platform_bits import PLATFORMS, fingerprint


def test_what_the_mixture_kernel_relies_on_holds() -> None:
    got = measure(n=2000, n_systems=2000)
    for k in (1, 2, 3, 4, 5):
        assert got[f"solve {k}x{k}"] == 0.0, got
        assert got[f"einsum ka,ka->k, k={k}, two lanes"] == 0.0, got
    assert got["einsum ka,ka->k, k=4, left to right"] > 0.0  # the order matters: the measure can tell
    for name in ("sin", "cos", "sqrt", "hypot", "square"):
        assert got[name] == 0.0, (name, got)
    if PLATFORMS.get(fingerprint()) == "x86-64-avx2":  # numpy's loops are the C library's there
        assert all(got[name] == 0.0 for name in ("exp", "log", "arctan2", "power(x, 3)")), got
    elif PLATFORMS.get(fingerprint()) == "x86-64-avx512":  # numpy's own SIMD loops: some last bits differ
        assert got["exp"] > 0.0 and got["arctan2"] > 0.0, got
