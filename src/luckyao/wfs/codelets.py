"""Straight-line DFT codelets, generated symbolically, for numba kernels.

Speed-only machinery: the generated statements stand for plain FFTs and sums, those of the
step-by-step model in ``wfs/shack_hartmann.py`` (``intensity_samples``: the FFT of each
sub-aperture's zero-padded field; ``intensity_spectra``; ``pixel_images``: the pixel sums),
computed with fewer operations (zero inputs and trivial twiddles pruned) for the compiled
exposure (``wfs/kernels.py``); the WFS physics is in the model.

A :class:`Codelet` records float32 statements of one SIMD lane: values are
terms ``(name, sign)`` or ``None`` (an exact zero), complex values pairs of
terms, so that multiplications by 0, +-1 and +-i cost nothing and zero inputs
prune the transform. :func:`dft` is the split-radix decomposition (Duhamel &
Hollmann 1984; Sorensen et al. 1986); :meth:`Codelet.source` keeps only the
statements that feed the requested outputs. Kernels embed the statements in a
loop over lanes, which LLVM vectorises; :func:`load_module` compiles them from
a file, so that numba caches them on disk (numba's front end takes seconds for
such long functions).
"""

import hashlib
import importlib.util
import os
import sys
import tempfile
from functools import cache
from pathlib import Path

import numpy as np

_ZERO = 1e-12


class Codelet:
    """Statements ``t<i> = expression`` of one lane, built term by term; their
    float32 constants ``K<i>`` (globals of the kernel) are in :attr:`constants`."""

    def __init__(self):
        self._statements = []  # (name, expression, names it reads)
        self.constants = {}

    @staticmethod
    def input(name: str):
        """The term of an input variable ``name``."""
        return (name, 1)

    def _constant(self, value: float) -> str:
        value = np.float32(value)
        for name, known in self.constants.items():
            if known == value:
                return name
        name = f"K{len(self.constants)}"
        self.constants[name] = value
        return name

    def combine(self, pairs):
        """Term ``sum(coefficient * term)``; zero terms and coefficients dropped."""
        pairs = [(term[0], term[1] * c) for term, c in pairs if term is not None and abs(c) > _ZERO]
        if not pairs:
            return None
        if len(pairs) == 1 and abs(abs(pairs[0][1]) - 1) < _ZERO:
            return (pairs[0][0], 1 if pairs[0][1] > 0 else -1)
        sign = 1 if any(c > 0 for _, c in pairs) else -1
        pairs = sorted(((name, sign * c) for name, c in pairs), key=lambda nc: nc[1] < 0)
        expression = ""
        for name, c in pairs:
            factor = name if abs(abs(c) - 1) < _ZERO else f"{name} * {self._constant(abs(c))}"
            expression += (" - " if c < 0 else " + ") + factor if expression else factor
        name = f"t{len(self._statements)}"
        self._statements.append((name, expression, [n for n, _ in pairs]))
        return (name, sign)

    # complex values: (re, im) pairs of terms
    def add(self, a, b, sign_b=1):
        return (self.combine([(a[0], 1), (b[0], sign_b)]), self.combine([(a[1], 1), (b[1], sign_b)]))

    def rotate(self, a, w: complex):
        """``a * w`` for a constant ``w``."""
        c, s = w.real, w.imag
        return (self.combine([(a[0], c), (a[1], -s)]), self.combine([(a[0], s), (a[1], c)]))

    @staticmethod
    def times_i(a, sign=1):
        """``sign * i * a`` (no statement)."""
        return (_negative(a[1]), a[0]) if sign > 0 else (a[1], _negative(a[0]))

    def source(self, outputs, indent: str) -> list[str]:
        """Lines (with ``indent``) of the statements that ``outputs`` (terms) need."""
        live = {t[0] for t in outputs if t is not None}
        for name, _, reads in reversed(self._statements):
            if name in live:
                live.update(reads)
        return [f"{indent}{name} = {expression}" for name, expression, _ in self._statements if name in live]


def _negative(term):
    return None if term is None else (term[0], -term[1])


def term_value(term) -> str:
    """Expression of a term (a float32 zero for ``None``)."""
    if term is None:
        return "np.float32(0.0)"
    return term[0] if term[1] > 0 else f"-{term[0]}"


def dft(codelet: Codelet, x: list) -> list:
    """Forward DFT ``X_k = sum_n x_n exp(-2 pi i k n / N)`` (N a power of 2) of
    complex values (pairs of terms, ``(None, None)`` for zero), split radix."""
    n = len(x)
    if all(v[0] is None and v[1] is None for v in x):
        return [(None, None)] * n
    if n == 1:
        return list(x)
    if n == 2:
        return [codelet.add(x[0], x[1]), codelet.add(x[0], x[1], -1)]
    u = dft(codelet, x[0::2])
    z1 = dft(codelet, x[1::4])
    z3 = dft(codelet, x[3::4])
    out = [None] * n
    quarter = n // 4
    for k in range(quarter):
        a = codelet.rotate(z1[k], _unit(-k, n))
        b = codelet.rotate(z3[k], _unit(-3 * k, n))
        s = codelet.add(a, b)
        d = codelet.add(a, b, -1)
        out[k] = codelet.add(u[k], s)
        out[k + n // 2] = codelet.add(u[k], s, -1)
        out[k + quarter] = codelet.add(u[k + quarter], Codelet.times_i(d, -1))
        out[k + 3 * quarter] = codelet.add(u[k + quarter], Codelet.times_i(d))
    return out


def _unit(k: int, n: int) -> complex:
    """``exp(2 pi i k / n)`` with exact 0 and +-1 parts."""
    angle = 2 * np.pi * k / n
    return complex(*(0.0 if abs(v) < _ZERO else v for v in (np.cos(angle), np.sin(angle))))


def load_module(name: str, source: str):
    """Import generated ``source`` as module ``luckyao_kernel_<name>_<digest>``.

    The source is written once to a file in this package's ``__pycache__/generated``
    (:func:`_kernel_directory`; a private temporary folder if that is read-only) so that
    numba's on-disk cache (``cache=True``) keeps its compiled functions between
    processes; the file name carries a digest of the source, so an existing
    file is never rewritten and a changed generator gives a new file.
    """
    digest = hashlib.sha256(source.encode()).hexdigest()[:16]
    module_name = f"luckyao_kernel_{name}_{digest}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    path = _kernel_directory() / f"{name}_{digest}.py"
    if not path.exists() or path.read_text() != source:
        partial = path.with_suffix(f".{os.getpid()}.tmp")
        partial.write_text(source)
        os.replace(partial, path)
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module


@cache
def _kernel_directory() -> Path:
    """Generated kernels live beside numba's own cache, in this package's
    ``__pycache__`` (a private temporary folder if that is read-only)."""
    directory = Path(__file__).resolve().parent / "__pycache__" / "generated"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        if os.access(directory, os.W_OK):
            return directory
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix="luckyao-kernels-"))
