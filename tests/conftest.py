"""Test-session setup.

OpenBLAS threads are pinned to one before numpy/scipy load: the core's per-track linear algebra
is on tiny matrices, and on this shared 2-core machine OpenBLAS's thread hand-off made
update_single up to 30x slower under load (3000 radar2d EKF updates: 8.9 s with the default
threads, 0.30 s with OPENBLAS_NUM_THREADS=1).
"""

from __future__ import annotations

import os
import sys

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

if "numpy" in sys.modules:  # pragma: no cover - only if a plugin imported numpy first
    import warnings

    warnings.warn("numpy was imported before tests/conftest.py; BLAS threads not pinned",
                  stacklevel=1)
