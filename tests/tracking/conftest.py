"""Pin OpenBLAS to one thread for the tracker tests.

The tracker's linear algebra is on 2x2 to 6x6 matrices; OpenBLAS by default splits even those
over all cores and spin-waits between them. On a machine shared with other work that made one
Kalman update cost 0.2-4 ms instead of ~25 us (measured: update_single 194-348 us with the
default, 23-26 us with one thread, under a load average of ~4 on 2 cores), and this suite 10x
slower. The environment variable works when it is set before numpy loads; if numpy (or scipy)
already loaded its OpenBLAS, the thread count is set through the library itself.
"""

from __future__ import annotations

import ctypes
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _pin_loaded_openblas() -> None:
    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "openblas" in line.split()[-1].lower() and ".so" in line}
    except OSError:
        return
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in ("openblas_set_num_threads", "openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                     "scipy_openblas_set_num_threads64_"):
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(1)
                break


import numpy  # noqa: E402, F401 - load numpy's OpenBLAS (with the variable above) before pinning
import scipy.linalg  # noqa: E402, F401 - and scipy's

_pin_loaded_openblas()
