"""fusion's one C extension, fusion.core._packed_step: the planned single-state step of
fusion.core.packed_step, C for its call cost (the same bits as numba's twin). Optional: an
install on a machine without a C compiler goes on without it and the step runs numba's twin
(about 1 us slower). Everything else about the package is in pyproject.toml."""

import numpy
from setuptools import Extension, setup

setup(ext_modules=[Extension(
    "fusion.core._packed_step", ["fusion/core/_packed_step.c"], include_dirs=[numpy.get_include()],
    # no fused multiply-add: the same bits as the numba kernels (compiled with fastmath off)
    extra_compile_args=["-O2", "-ffp-contract=off"], optional=True)])
