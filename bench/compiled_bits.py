"""Which of the float64 operations the shipped tracker calls give the same bits compiled (numba)
as through numpy, on this machine: what a scan compiled further could move into its kernels and
still give the pinned results (tests/tracking/test_scan_digest.py), and what must stay a numpy
call between kernels. Not a timing; `python -m bench.compiled_bits` (add `--avx2` to run it again
as an AVX2 machine would: numpy's AVX-512 loops off, OpenBLAS's Haswell kernels; see
tests/platform_bits.py).

For each operation, the fraction of N seeded random inputs (float64; systems symmetric positive
definite, as S and P are) whose result differs in any bit between numpy (one call on the whole
batch, as the tracker makes it) and the same operation written in a numba kernel (one call per
row inside the kernel: `math.exp`, `np.linalg.solve`, `A @ B`, a sum of products in two orders). A row
differs when any of its elements does. The compiled solve and products are numba's LAPACK and
BLAS bindings (scipy's OpenBLAS), numpy's its own OpenBLAS: two builds, compared here."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numba
import numpy as np

N = 200_000
N_SYSTEMS = 20_000


@numba.njit(cache=True)
def _unary(a: np.ndarray, op: int) -> np.ndarray:
    out = np.empty_like(a)
    for i in range(a.size):
        x = a[i]
        if op == 0:
            out[i] = math.exp(x)
        elif op == 1:
            out[i] = math.log(x)
        elif op == 2:
            out[i] = math.sin(x)
        elif op == 3:
            out[i] = math.cos(x)
        elif op == 4:
            out[i] = math.sqrt(x)
        elif op == 5:
            out[i] = math.pow(x, 3.0)
        else:
            out[i] = x * x
    return out


@numba.njit(cache=True)
def _binary(a: np.ndarray, b: np.ndarray, op: int) -> np.ndarray:
    out = np.empty_like(a)
    for i in range(a.size):
        out[i] = math.atan2(a[i], b[i]) if op == 0 else math.hypot(a[i], b[i])
    return out


@numba.njit(cache=True)
def _solve(S: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty_like(b)
    for i in range(S.shape[0]):
        out[i] = np.linalg.solve(S[i], b[i])
    return out


@numba.njit(cache=True)
def _matmul(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    out = np.empty((A.shape[0], A.shape[1], B.shape[2]))
    for i in range(A.shape[0]):
        out[i] = A[i] @ B[i]
    return out


@numba.njit(cache=True)
def _dot_rows(y: np.ndarray, w: np.ndarray, lanes: bool) -> np.ndarray:
    """Each row's sum of products: left to right, or in two lanes as numpy's einsum sums a short
    contiguous axis (the even terms, the odd terms, then the two: found here for 2 to 5 terms)."""
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        if lanes:
            even = y[i, 0] * w[i, 0]
            for j in range(2, y.shape[1], 2):
                even += y[i, j] * w[i, j]
            if y.shape[1] > 1:
                odd = y[i, 1] * w[i, 1]
                for j in range(3, y.shape[1], 2):
                    odd += y[i, j] * w[i, j]
                even += odd
            out[i] = even
        else:
            s = y[i, 0] * w[i, 0]
            for j in range(1, y.shape[1]):
                s += y[i, j] * w[i, j]
            out[i] = s
    return out


def _differ(a: np.ndarray, b: np.ndarray) -> float:
    """The fraction of rows (first axis) of a and b that differ in any bit (NaN equal to NaN)."""
    ne = a.view(np.uint64) != b.view(np.uint64)
    return float(np.mean(ne.reshape(len(ne), -1).any(axis=1)))


def measure(n: int = N, n_systems: int = N_SYSTEMS) -> dict[str, float]:
    """The fraction of differing rows of each operation (see the module docstring)."""
    rng = np.random.default_rng(20261207)
    x = rng.normal(size=n) * 10.0
    y = rng.normal(size=n) * 10.0
    a = np.abs(x) + 1e-3
    out = {
        "exp": _differ(np.exp(-a), _unary(-a, 0)),
        "log": _differ(np.log(a), _unary(a, 1)),
        "arctan2": _differ(np.arctan2(y, x), _binary(y, x, 0)),
        "power(x, 3)": _differ(a**3, _unary(a, 5)),
        "sin": _differ(np.sin(x), _unary(x, 2)),
        "cos": _differ(np.cos(x), _unary(x, 3)),
        "sqrt": _differ(np.sqrt(a), _unary(a, 4)),
        "hypot": _differ(np.hypot(x, y), _binary(x, y, 1)),
        "square": _differ(np.square(x), _unary(x, 6)),
    }
    for k in (1, 2, 3, 4, 5):
        M = rng.normal(size=(n_systems, k, k))
        S = M @ np.swapaxes(M, 1, 2) + 0.5 * np.eye(k)
        b = rng.normal(size=(n_systems, k, 1))
        B = rng.normal(size=(n_systems, k, k))
        out[f"solve {k}x{k}"] = _differ(np.linalg.solve(S, b), _solve(S, b))
        out[f"matmul {k}x{k}"] = _differ(M @ B, _matmul(M, B))
        w = rng.normal(size=(n_systems, k))
        v = rng.normal(size=(n_systems, k))
        e = np.einsum("ka,ka->k", v, w)
        out[f"einsum ka,ka->k, k={k}, left to right"] = _differ(e, _dot_rows(v, w, False))
        out[f"einsum ka,ka->k, k={k}, two lanes"] = _differ(e, _dot_rows(v, w, True))
    return out


def _loops() -> str:
    """Which of numpy's loops this machine runs for the float64 functions that differ (numpy's
    public introspection: X86_V4 is its AVX-512 code) and OpenBLAS's kernels (threadpoolctl)."""
    from numpy.lib.introspect import opt_func_info
    from threadpoolctl import threadpool_info

    info = opt_func_info(func_name="^(exp|log|arctan2|power)$", signature="float64")
    loops = ", ".join(f"{name} {next(iter(sig.values()))['current']}" for name, sig in sorted(info.items()))
    blas = sorted({f"{i.get('internal_api')} {i.get('version')} {i.get('architecture')}" for i in threadpool_info()
                   if i.get("user_api") == "blas"})
    return f"numpy's loops {loops}; BLAS {'; '.join(blas) or 'unknown'}"


def run(*, quick: bool = False) -> dict[str, float]:
    print(f"compiled (numba {numba.__version__}) against numpy {np.__version__}, float64 ({_loops()}); "
          "rows whose bits differ:")
    got = measure()
    for name, v in got.items():
        print(f"  {name:<36} {v * 100:7.3f} %")
    return {"compiled_bits_" + "_".join(k.replace(",", "").split()): v for k, v in got.items()}


if __name__ == "__main__":
    if "--avx2" in sys.argv[1:]:
        env = dict(os.environ, NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL", OPENBLAS_CORETYPE="Haswell")
        sys.exit(subprocess.call([sys.executable, "-m", "bench.compiled_bits"], env=env))
    run()
