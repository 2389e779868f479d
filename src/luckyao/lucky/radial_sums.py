"""Compiled encircled-energy sums of lucky imaging: a frame's radial sums about one or several
centres read from its spectrum (:class:`.metrics.EncircledEnergy`), and the radius where a
sampled curve first reaches a level (the d50).
"""

import math

import numba
import numpy as np

from ..simd import fmuladd

# numba's disk cache keys a kernel by its own file: this digest of the intrinsics the kernels
# inline makes an edit of theirs recompile them (tests/test_simd.py keeps it current)
# intrinsics digest (simd.py): 86b3bc4b14f3bbee


@numba.njit(cache=True, nogil=True, fastmath={"contract"})
def radial_energy(spectrum, centre, fy, fx, row_end, bin_of, weight, out):  # pragma: no cover (jit)
    """``out[b] = sum_k weight_k Re(S_k exp(2 pi i f_k.c))`` over the kept half-plane
    frequencies ``k`` of radial bin ``b``. ``spectrum`` (n, n/2 + 1) complex64 (rfft2);
    row ``ky`` keeps columns ``0..row_end[ky] - 1`` whose bins are ``bin_of[ky, :]`` and
    weights ``weight[ky, :]`` (float64); ``fy`` (n,), ``fx`` (n/2+1,) [cycles/pixel]."""
    out[:] = 0.0
    m = fx.size
    px_re = np.empty(m)
    px_im = np.empty(m)
    for x in range(m):
        a = 2 * np.pi * centre[1] * fx[x]
        px_re[x] = math.cos(a)
        px_im[x] = math.sin(a)
    term = np.empty(m)
    for y in range(spectrum.shape[0]):
        a = 2 * np.pi * centre[0] * fy[y]
        cy, sy = math.cos(a), math.sin(a)
        end, row, w, bins = row_end[y], spectrum[y], weight[y], bin_of[y]
        for x in range(end):  # a row's terms first (vectorised), then added to their bins in order
            z = row[x]
            pr = cy * px_re[x] - sy * px_im[x]
            pi = cy * px_im[x] + sy * px_re[x]
            term[x] = w[x] * (z.real * pr - z.imag * pi)
        for x in range(end):
            out[bins[x]] += term[x]


RADIAL_CENTRES_INNER = 8
"""From this many centres on, :func:`radial_energies` vectorises over the centres, below it over
a row's frequencies (the same operations on each value: the same sums bit for bit)."""


@numba.njit(cache=True, nogil=True)
def radial_energies(spectrum, centres, fy, fx, row_end, bin_of, weight, out):  # pragma: no cover (jit)
    """:func:`radial_energy` about several centres ``centres`` (m, 2) at once, ``out`` (m, bins):
    each frequency's value, bin and weight read once for every centre. The phases
    ``exp(2 pi i f c)`` along each axis follow the recurrence ``p(f + 1/n) = p(f) exp(2 pi i c / n)``
    from values computed directly wherever the frequency does not step by 1/n (the zero and the
    Nyquist frequency), so that there are no trigonometric functions per frequency and centre; the
    rounding this adds, ~1e-14 of the spectrum, is far below the float32 spectrum's own.

    Each term ``w Re(S p_y p_x)`` is the same sequence of operations whatever the number of centres,
    its fused multiply-adds stated (:func:`luckyao.simd.fmuladd`, no fast-math flags: the same bits
    whether the kernel was compiled in this process or loaded from numba's cache), and each bin's
    terms are added in the order of the rows, then the columns: the sums are bit for bit the same
    for a centre alone or among others. Vectorised over a row's frequencies for fewer than
    :data:`RADIAL_CENTRES_INNER` centres (a row's terms first, then added to their bins, each bin
    getting at most one term per row), over the centres for more."""
    m, h = centres.shape[0], fx.size
    px_re, px_im = np.empty((m, h)), np.empty((m, h))
    _phases(fx, centres[:, 1], px_re, px_im)
    py_re, py_im = np.empty((m, fy.size)), np.empty((m, fy.size))
    _phases(fy, centres[:, 0], py_re, py_im)
    if m < RADIAL_CENTRES_INNER:
        out[:] = 0.0
        zr, zi, term = np.empty(h), np.empty(h), np.empty(h)
        for y in range(spectrum.shape[0]):
            end, row, w, bins = row_end[y], spectrum[y], weight[y], bin_of[y]
            for x in range(end):
                zr[x], zi[x] = row[x].real, row[x].imag
            for c in range(m):
                cy, sy, re, im = py_re[c, y], py_im[c, y], px_re[c], px_im[c]
                for x in range(end):
                    pr = fmuladd(cy, re[x], -(sy * im[x]))
                    pi = fmuladd(sy, re[x], cy * im[x])
                    term[x] = fmuladd(zr[x], pr, -(zi[x] * pi))
                to = out[c]
                for x in range(end):
                    to[bins[x]] = fmuladd(w[x], term[x], to[bins[x]])
        return
    sums = np.zeros((out.shape[1], m))  # (bin, centre): a frequency's centres side by side
    re_t, im_t = np.ascontiguousarray(px_re.T), np.ascontiguousarray(px_im.T)
    cy_t, sy_t = np.ascontiguousarray(py_re.T), np.ascontiguousarray(py_im.T)
    for y in range(spectrum.shape[0]):
        cy, sy = cy_t[y], sy_t[y]
        for x in range(row_end[y]):
            z = spectrum[y, x]
            zr, zi, w = np.float64(z.real), np.float64(z.imag), weight[y, x]
            to, re, im = sums[bin_of[y, x]], re_t[x], im_t[x]
            for c in range(m):
                pr = fmuladd(cy[c], re[c], -(sy[c] * im[c]))
                pi = fmuladd(sy[c], re[c], cy[c] * im[c])
                to[c] = fmuladd(w, fmuladd(zr, pr, -(zi * pi)), to[c])
    for b0 in range(0, sums.shape[0], 64):  # transposed in blocks: out's rows written in runs
        b1 = min(b0 + 64, sums.shape[0])
        for c in range(m):
            for b in range(b0, b1):
                out[c, b] = sums[b, c]


@numba.njit(inline="always")
def _phases(f, c, re, im):  # pragma: no cover (jit)
    """``re[j, k] + i im[j, k] = exp(2 pi i f[k] c[j])`` for frequencies ``f`` [cycles/pixel] spaced
    by 1/n but where they wrap (:func:`radial_energies`): each step a multiplication. Inlined: its
    operations are its caller's, however that was compiled."""
    n = f.size if f[-1] < 0 else 2 * (f.size - 1)  # fftfreq(n) or rfftfreq(n)
    for j in range(c.size):
        step_re, step_im = math.cos(2 * np.pi * c[j] / n), math.sin(2 * np.pi * c[j] / n)
        for k in range(f.size):
            if k == 0 or abs(f[k] - f[k - 1] - 1.0 / n) > 0.25 / n:
                a = 2 * np.pi * c[j] * f[k]
                re[j, k], im[j, k] = math.cos(a), math.sin(a)
            else:
                r, i = re[j, k - 1], im[j, k - 1]
                re[j, k], im[j, k] = r * step_re - i * step_im, r * step_im + i * step_re


@numba.njit(cache=True, nogil=True)
def first_crossing(radii, values, level, out):  # pragma: no cover (jit)
    """``out[i]``: the radius where ``values[i]`` (m, n_r), sampled on ``radii`` (n_r,) >= 4,
    first reaches ``level``: the first grid point at or above it, then bisection (40 halvings
    of the bracket, to 1e-12 of a grid step) on the cubic Lagrange interpolant through the
    four grid points around it; NaN if none is, or the first is.
    """
    n_r = radii.size
    for i in range(values.shape[0]):
        v = values[i]
        j = 0
        while j < n_r and not v[j] >= level:
            j += 1
        if j == 0 or j == n_r:
            out[i] = np.nan
            continue
        i0 = min(max(j - 2, 0), n_r - 4)
        lo, hi = radii[j - 1], radii[j]
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            total = 0.0
            for a in range(4):  # the Lagrange basis over the 4 nodes
                term = v[i0 + a]
                for b in range(4):
                    if b != a:
                        term *= (mid - radii[i0 + b]) / (radii[i0 + a] - radii[i0 + b])
                total += term
            if total < level:
                lo = mid
            else:
                hi = mid
        out[i] = 0.5 * (lo + hi)
