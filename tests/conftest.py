"""Imported before any test module: one thread for BLAS and numba, as the workflow's jobs run
(``luckyao.threads``: OpenBLAS splits some products over its threads, and their sums then
round otherwise, so the numbers would depend on the machine's cores), then the package, so that
the BLAS kernels it pins (``OPENBLAS_CORETYPE``, src/luckyao/__init__.py) are set too before
numpy is loaded, however pytest is started: a test comparing numbers with an earlier run gets
them on any machine."""

from luckyao.threads import pin_one_thread  # imports the package (not numpy): the BLAS kernels pinned

pin_one_thread(override=False)
