"""Imported before any test module: one thread for BLAS and numba, as the workflow's jobs run
(``luckyao.api.ONE_THREAD``: OpenBLAS splits some products over its threads, and their sums then
round otherwise, so the numbers would depend on the machine's cores), then the package, so that
the BLAS kernels it pins (``OPENBLAS_CORETYPE``, src/luckyao/__init__.py) are set too before
numpy is loaded, however pytest is started: a test comparing numbers with an earlier run gets
them on any machine."""

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import luckyao  # noqa: E402, F401
