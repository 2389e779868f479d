"""The environment of a step: the numerical libraries pinned to one thread, as every
workflow step runs (the rules' command prefix), ``luckyao.run_case``'s steps, the test
suite (``tests/conftest.py``) and the benchmarks.

OpenBLAS splits some matrix products over its threads, and their sums then round
otherwise, so the numbers would depend on the machine's cores; numba and OpenMP are
pinned alike. The variables take effect only when set before numpy, BLAS or numba are
first imported, so this module imports neither (nor does the package's ``__init__``,
which pins the BLAS kernels, ``OPENBLAS_CORETYPE``): import it first and call
:func:`pin_one_thread`, or give :data:`ONE_THREAD` to a child process's environment.
"""

import os

ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}
"""The environment of one thread: each library's thread count, 1."""


def pin_one_thread(override: bool = True) -> None:
    """Set :data:`ONE_THREAD` in this process's environment (``override=False``: only the
    variables not set already). Call before numpy, BLAS or numba are imported."""
    for name, value in ONE_THREAD.items():
        if override:
            os.environ[name] = value
        else:
            os.environ.setdefault(name, value)


STUDY_JOB = "LUCKYAO_STUDY_JOB"
"""Environment variable set to ``1`` in the command of every job of the workflow
(``LUCKYAO`` in ``workflow/rules/common.smk``), whose working folder is then its study
folder: such a process holds the study's run lock while it lives (``jobs.live_run``) and
may set a bad input of the study aside (``io.datasets``). Nothing else does either."""


def is_study_job() -> bool:
    """Whether this process is a job of the workflow (:data:`STUDY_JOB`)."""
    return os.environ.get(STUDY_JOB) == "1"


def shell_prefix() -> str:
    """:data:`ONE_THREAD` as a shell command's prefix, ``"OMP_NUM_THREADS=1 ... "``."""
    return "".join(f"{name}={value} " for name, value in ONE_THREAD.items())
