"""Imported before any test module: the package first, so that the BLAS kernels it pins
(``OPENBLAS_CORETYPE``, src/luckyao/__init__.py) are set before numpy is loaded, however pytest
is started, and a test comparing numbers with an earlier run gets them on any machine."""

import luckyao  # noqa: F401
