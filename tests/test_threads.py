"""The one-thread environment (``luckyao.threads``) is importable before numpy, as it must be."""

import subprocess
import sys

from luckyao.threads import ONE_THREAD, shell_prefix


def test_the_one_thread_module_imports_no_numpy():
    """Importing it (and the package's ``__init__``) loads neither numpy nor numba, and the
    BLAS kernels are pinned on the way: the variables can still take effect."""
    code = (
        "import os, sys; import luckyao.threads as t; t.pin_one_thread(); "
        "assert not {'numpy', 'numba'} & set(sys.modules), sorted(sys.modules); "
        "assert os.environ['OPENBLAS_CORETYPE'] and os.environ['OPENBLAS_NUM_THREADS'] == '1'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_rules_prefix_is_the_environment():
    assert shell_prefix() == "".join(f"{k}=1 " for k in ONE_THREAD)
    assert set(ONE_THREAD) == {"OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"}
