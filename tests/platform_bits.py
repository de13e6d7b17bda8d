"""Which last bits this machine gives for the float64 operations the tracker uses, as a short
fingerprint, and the pinned results that hold for it.

numpy picks some float64 loops by CPU: with AVX-512 (X86_V4) arctan2, exp, log, power and tan
come from its SIMD (SVML) code, which differs from the C library's in the last bit for 0.1-7 % of
inputs (measured 2026-12-05 on 200 000 normal draws: arctan2 7.4 %, power 5.4 %, exp 4.7 %, tan
0.5 %, log 0.09 %; sin, cos and sqrt equal), and with AVX2 or less they equal the C library's.
OpenBLAS picks its kernels by CPU too (SkylakeX, Haswell/Zen, ...), which reaches np.linalg.solve
and small matrix products. The tracker is bit-identical run to run and under any arrival order
on one machine, but not between machines that differ in these: the pinned digests of the scan
(tests/tracking/test_scan_digest.py) and of the recording (tests/io/test_recording_same.py)
changed under `NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL"` and under `OPENBLAS_CORETYPE=Haswell`.

So a result pinned bit for bit is pinned per fingerprint (PLATFORMS): `pinned` gives the value
for this machine's, and skips, saying why, on a machine whose fingerprint has none. To pin one
for another machine, run the generator named by the test on it and add its fingerprint here.
The AVX2 entries were taken on the AVX-512 machine with both variables above set, which selects
the same numpy loops and OpenBLAS kernels an AVX2 machine (Haswell and later Intel, Zen 1-3)
runs.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from functools import cache
from typing import TypeVar

import numpy as np
import pytest

T = TypeVar("T")

# fingerprint -> the name pinned results are kept under
PLATFORMS = {
    "2601a28f9e8ced56": "x86-64-avx512",  # numpy X86_V4 loops, OpenBLAS SkylakeX kernels (this machine)
    "3ee2154722df7126": "x86-64-avx2",  # numpy X86_V3 loops (the C library's), OpenBLAS Haswell kernels
}


@cache
def fingerprint() -> str:
    """16 hex digits of a hash of the bits numpy gives here for the CPU-dispatched operations the
    tracker uses: the transcendental ufuncs, powers, and batched small solves, inverses, Cholesky
    factors and matrix products (OpenBLAS)."""
    rng = np.random.default_rng(20261205)
    x, y = rng.normal(size=4096) * 10.0, rng.normal(size=4096) * 10.0
    a = np.abs(x)
    M = rng.normal(size=(64, 5, 5))
    S = M @ np.swapaxes(M, 1, 2) + 5.0 * np.eye(5)  # symmetric positive definite
    b = rng.normal(size=(64, 5, 1))
    parts = [np.arctan2(y, x), np.exp(-a), np.log(a), a**3, a**2.5, np.sqrt(a), np.hypot(x, y), np.sin(x),
             np.cos(x), np.tan(x), np.linalg.solve(S, b), np.linalg.solve(S[:, :2, :2], b[:, :2]), np.linalg.inv(S),
             np.linalg.cholesky(S), M @ S, M[0] @ S[0], np.einsum("nij,njk->nik", M, S),
             np.einsum("ij,ij->i", x.reshape(-1, 4), y.reshape(-1, 4))]
    h = hashlib.sha256()
    for p in parts:
        h.update(np.ascontiguousarray(p).tobytes())
    return h.hexdigest()[:16]


def pinned(table: Mapping[str, T], what: str) -> T:
    """table[the name of this machine's fingerprint], or a skip that says why there is none."""
    fp = fingerprint()
    name = PLATFORMS.get(fp)
    if name is None or name not in table:
        pytest.skip(f"{what} is pinned bit for bit on {sorted(table)}; this machine's floating-point fingerprint "
                    f"{fp} ({'unknown' if name is None else name}) has no pinned value (numpy's CPU dispatch or "
                    "OpenBLAS's kernels give other last bits here: see tests/platform_bits.py)")
    return table[name]
