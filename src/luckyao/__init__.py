"""luckyao: LGS-assisted lucky imaging, simulated and validated against theory.

The Python interface (``luckyao.api``, loaded on first use): ``open_case``,
``open_telemetry``, ``open_figure``, ``draw``, ``load_study``, ``run_case``,
``export_fits``; a walk-through in ``docs/examples/tutorial.py``.
"""

import importlib
import os

# OpenBLAS picks its kernels by the CPU it finds, and kernels of different CPUs round
# differently (matrix products: the reconstructors, the encircled energies): the same config
# and seed would give other bits on another machine. Its AVX2 (Haswell) kernels run on every
# x86-64 CPU of the last decade; effective when set before numpy is first imported (run.sh and
# the workflow's jobs set it in their environment).
os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")

from .version import __version__  # noqa: E402  (after the BLAS pinning: numpy must not load first)

_API = ("open_case", "open_telemetry", "open_figure", "draw", "load_study", "run_case", "export_fits")
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    # Loaded on first use, by name: every workflow step imports this package, and neither
    # its start-up nor its code inputs (jobs/code_deps.py follows import statements)
    # should include the interface, which no step uses.
    if name in _API:
        return getattr(importlib.import_module("luckyao.api"), name)
    raise AttributeError(f"module 'luckyao' has no attribute {name!r}")
