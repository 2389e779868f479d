"""Compiled image helpers of lucky imaging: a rolled frame's central crop and the Fourier
shift's phase ramps (:mod:`.registration`, :mod:`.cropped`); the half-maximum region of a
peak and the trigonometric interpolant's Dirichlet kernel (the FWHM, :mod:`.metrics`).
"""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def crop_rolled(frames, shifts, which, out):  # pragma: no cover (jit)
    """``out[j]`` (c, c) = the central ``c`` square (rows and columns ``n/2 - c/2 ..``) of
    ``roll(frames[j], shifts[j])`` (``np.roll`` semantics), for every ``j`` with ``which[j]``;
    ``frames`` (k, n, n), ``shifts`` (k, 2) int64 (y, x), ``out`` (>= k, c, c)."""
    k, n, _ = frames.shape
    c = out.shape[1]
    lo = n // 2 - c // 2
    for j in range(k):
        if not which[j]:
            continue
        x0 = (lo - shifts[j, 1]) % n
        first = min(c, n - x0)  # columns before the source row wraps
        for y in range(c):
            src = frames[j, (lo + y - shifts[j, 0]) % n]
            dst = out[j, y]
            for x in range(first):
                dst[x] = src[x0 + x]
            for x in range(first, c):
                dst[x] = src[x - first]


@numba.njit(cache=True, nogil=True)
def phase_ramps(spectra, shifts):  # pragma: no cover (jit)
    """``spectra[j] *= exp(-2 pi i fy s_y) exp(-2 pi i fx s_x)`` (complex64) for the real FFTs
    ``spectra`` (k, n, n/2 + 1) of n x n frames (frequencies ``fy`` numpy's ``fftfreq(n)``, ``fx``
    its ``rfftfreq(n)``, cycles/pixel) and shifts ``shifts`` (k, 2) (y, x) [pixel]: the frames
    moved by ``s`` (the Fourier shift theorem)."""
    k, n, h = spectra.shape
    ramp_y = np.empty(n, np.complex64)
    ramp_x = np.empty(h, np.complex64)
    for j in range(k):
        for y in range(n):
            a = -2 * np.pi * (y if y < (n + 1) // 2 else y - n) / n * shifts[j, 0]
            ramp_y[y] = np.complex64(complex(math.cos(a), math.sin(a)))
        for x in range(h):
            a = -2 * np.pi * x / n * shifts[j, 1]
            ramp_x[x] = np.complex64(complex(math.cos(a), math.sin(a)))
        for y in range(n):
            row = spectra[j, y]
            for x in range(h):
                row[x] = row[x] * ramp_y[y] * ramp_x[x]


@numba.njit(cache=True, nogil=True)
def component(values, threshold, y0, x0, inside):  # pragma: no cover (jit)
    """The 4-connected component of ``values >= threshold`` (m, n) holding ``(y0, x0)``
    (which must qualify) as ``inside`` (m, n) bool, as ``scipy.ndimage.label``'s default
    structure labels it. Returns (pixels, first row, last row, first column, last column)."""
    m, n = values.shape
    inside[:] = False
    stack = np.empty(m * n, np.int64)
    stack[0] = y0 * n + x0
    inside[y0, x0] = True
    top = 1
    count = 0
    r0, r1, c0, c1 = y0, y0, x0, x0
    while top:
        top -= 1
        p = stack[top]
        y, x = p // n, p % n
        count += 1
        r0, r1, c0, c1 = min(r0, y), max(r1, y), min(c0, x), max(c1, x)
        for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            yy, xx = y + dy, x + dx
            if 0 <= yy < m and 0 <= xx < n and not inside[yy, xx] and values[yy, xx] >= threshold:
                inside[yy, xx] = True
                stack[top] = yy * n + xx
                top += 1
    return count, r0, r1, c0, c1


@numba.njit(cache=True, nogil=True)
def dilate(inside, out):  # pragma: no cover (jit)
    """``out`` = binary dilation of ``inside`` (m, n) bool by the 3 x 3 square (as
    ``scipy.ndimage.binary_dilation`` with ``structure=np.ones((3, 3))``, outside False)."""
    m, n = inside.shape
    out[:] = False
    for y in range(m):
        for x in range(n):
            if inside[y, x]:
                for yy in range(max(y - 1, 0), min(y + 2, m)):
                    for xx in range(max(x - 1, 0), min(x + 2, n)):
                        out[yy, xx] = True


@numba.njit(cache=True, nogil=True)
def dirichlet(j, up, table, out):  # pragma: no cover (jit)
    """``out[p, y'] = Re D(j_p / up - y')`` (len(j), n), ``D`` the Dirichlet kernel of
    ``metrics._dirichlet``: ``(-1)^y' sin(pi y_p) table[(j_p - up y') mod len(table)]``,
    ``table[m]`` = ``cot`` (even n) or ``1 / sin`` (odd n) of ``pi m / (up n)``; on whole
    pixels (``j_p`` a multiple of ``up``) n at ``y' = y_p mod n``, else 0."""
    n = out.shape[1]
    period = table.size
    for p in range(j.size):
        jp = j[p]
        row = out[p]
        if jp % up == 0:
            row[:] = 0.0
            row[(jp // up) % n] = n
            continue
        s = math.sin(math.pi * ((jp % (2 * up)) / up))
        for y in range(n):
            v = s * table[(jp - up * y) % period]
            row[y] = -v if y % 2 else v
