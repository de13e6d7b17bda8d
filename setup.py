"""fusion's one C extension, fusion.core._single: the single-state filter calls of
fusion.core.single (predict, update and the fused step), C for their call cost (the same bits as
their numba twins), and ExtendedKalmanFilter's predict and update as C methods that make them
(fusion/core/_filter_calls.c). Optional: an install on a machine without a C compiler goes on
without it and those calls run the numba twins (1-2 us slower per call) and the filter's methods
their Python twins. Everything else about the package is in pyproject.toml."""

import numpy
from setuptools import Extension, setup

setup(ext_modules=[Extension(
    "fusion.core._single", ["fusion/core/_single.c", "fusion/core/_filter_calls.c"],
    depends=["fusion/core/_single.h"], include_dirs=[numpy.get_include()],
    # no fused multiply-add: the same bits as the numba kernels (compiled with fastmath off)
    extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)])
