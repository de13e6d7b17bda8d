"""One BLAS thread: the tracker's algebra is on 2x2 to 6x6 matrices.

OpenBLAS by default splits even those over every core and spin-waits between them; on a
machine doing other work that made one Kalman update cost 0.2-0.35 ms instead of ~25 us
(measured on this project's 2-core machines). The command lines, the benchmarks and the tests
call `pin_blas_threads()`; a program embedding fusion should do the same (or set
OPENBLAS_NUM_THREADS=1 before numpy loads).
"""

from __future__ import annotations


def pin_blas_threads(n: int = 1) -> None:
    """Limit every BLAS library loaded in this process (numpy's, scipy's) to n threads."""
    import numpy  # noqa: F401 - load numpy's and scipy's BLAS so that the limit reaches them
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n, user_api="blas")
