"""Compiled kernels of the layer tomography's solve: the ray tracing, the gradient, the prior's
Laplacian, the preconditioner's per-frequency products and the PCG's vector updates.

Speed-only machinery: each stands for the numpy formula its docstring gives (the models are in
:mod:`.operators`, :mod:`.prior`, :mod:`.preconditioner` and :mod:`.solver`), in the arrays'
dtype (float32 in the study), one pass over memory where numpy made several, and no matrix
stored. The ray tracing and the gradient add their terms in the numpy formulas' order: the same
bits in float64 (in float32 the stencil's weights are float32, where numpy multiplied float64
weights); the prior, the preconditioner and the dot products group their sums otherwise (dot
products accumulate in float64). tests/test_layer_tomography_kernels.py holds the numpy formulas.
"""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def trace(layers, corners, weights, phase):  # pragma: no cover (jit)
    """``phase[a, b] = sum_l sum_(dr, dc) w_l[2 dr + dc] layers[l, r_l + dr + a, c_l + dc + b]``:
    one beacon's bilinear stencils (``corners`` (n_layers, 2) int64 (column, row), ``weights``
    (n_layers, 4) in the layers' dtype), summed layer by layer, tap by tap."""
    m = phase.shape[0]
    for a in range(m):
        out = phase[a]
        out[:] = 0
        for layer in range(layers.shape[0]):
            c0, r0 = corners[layer, 0], corners[layer, 1]
            w00, w01, w10, w11 = weights[layer, 0], weights[layer, 1], weights[layer, 2], weights[layer, 3]
            top = layers[layer, r0 + a, c0 : c0 + m + 1]
            bottom = layers[layer, r0 + a + 1, c0 : c0 + m + 1]
            for b in range(m):
                value = out[b] + w00 * top[b]
                value = value + w01 * top[b + 1]
                value = value + w10 * bottom[b]
                out[b] = value + w11 * bottom[b + 1]


@numba.njit(cache=True, nogil=True)
def trace_adjoint_add(phase, corners, weights, layers):  # pragma: no cover (jit)
    """``layers[l, r_l + dr + a, c_l + dc + b] += w_l[2 dr + dc] phase[a, b]`` (:func:`trace`'s
    adjoint), added tap by tap. Written as a gather over each layer sample from the phase padded
    by one zero sample on every side (``0 + x`` is ``x``: the same bits as the scatter)."""
    m = phase.shape[0]
    padded = np.zeros((m + 2, m + 2), dtype=phase.dtype)
    padded[1 : m + 1, 1 : m + 1] = phase
    for layer in range(layers.shape[0]):
        c0, r0 = corners[layer, 0], corners[layer, 1]
        w00, w01, w10, w11 = weights[layer, 0], weights[layer, 1], weights[layer, 2], weights[layer, 3]
        for a in range(m + 1):  # layer row r0 + a: pupil rows a (dr = 0) and a - 1 (dr = 1)
            out = layers[layer, r0 + a, c0 : c0 + m + 1]
            same, above = padded[a + 1], padded[a]
            for b in range(m + 1):
                value = out[b] + w00 * same[b + 1]
                value = value + w01 * same[b]
                value = value + w10 * above[b + 1]
                out[b] = value + w11 * above[b]


@numba.njit(cache=True, nogil=True)
def edge_differences(phase, rows, columns, weights, side, slopes):  # pragma: no cover (jit)
    """``slopes[0, k]``: the trapezoid mean (``weights``, ``o + 1`` samples) of sub-aperture ``k``'s
    right edge less its left edge's, over ``side`` (``d``); ``slopes[1, k]``: its top edge's less
    its bottom edge's. Sub-aperture ``k`` spans samples ``rows[k] .. rows[k] + o`` and
    ``columns[k] .. columns[k] + o``; each mean summed from its first sample."""
    o = weights.shape[0] - 1
    for k in range(rows.shape[0]):
        r, c = rows[k], columns[k]
        right, left = weights[0] * phase[r, c + o], weights[0] * phase[r, c]
        top, bottom = weights[0] * phase[r + o, c], weights[0] * phase[r, c]
        for t in range(1, o + 1):
            right = right + weights[t] * phase[r + t, c + o]
            left = left + weights[t] * phase[r + t, c]
            top = top + weights[t] * phase[r + o, c + t]
            bottom = bottom + weights[t] * phase[r, c + t]
        slopes[0, k] = (right - left) / side
        slopes[1, k] = (top - bottom) / side


@numba.njit(cache=True, nogil=True)
def edge_differences_adjoint(slopes, rows, columns, weights, side, phase):  # pragma: no cover (jit)
    """``phase = G^T slopes`` (:func:`edge_differences`' adjoint) as numpy would compute it: the
    slopes over ``d`` on the (n, n) grid ``g``; the adjoint differences ``t_x`` (n, m), ``t_y``
    (m, n) (``+g`` at each sub-aperture's far edge, then ``-g`` at its near one); then for each
    edge sample ``t`` in turn, ``phase`` rows ``t, t + o, ..`` ``+= w_t t_x`` and columns ``+= w_t t_y``."""
    m = phase.shape[0]
    o = weights.shape[0] - 1
    n = (m - 1) // o
    gx = np.zeros((n, n), dtype=phase.dtype)
    gy = np.zeros((n, n), dtype=phase.dtype)
    for k in range(rows.shape[0]):
        gx[rows[k] // o, columns[k] // o] = slopes[0, k] / side
        gy[rows[k] // o, columns[k] // o] = slopes[1, k] / side
    tx = np.zeros((n, m), dtype=phase.dtype)
    ty = np.zeros((m, n), dtype=phase.dtype)
    for a in range(n):
        for b in range(n):
            tx[a, o * b + o] += gx[a, b]
            ty[o * a + o, b] += gy[a, b]
    for a in range(n):
        for b in range(n):
            tx[a, o * b] -= gx[a, b]
            ty[o * a, b] -= gy[a, b]
    phase[:] = 0
    for t in range(o + 1):
        w = weights[t]
        for a in range(n):
            to, source = phase[t + o * a], tx[a]
            for c in range(m):
                to[c] += w * source[c]
        for r in range(m):
            to, source = phase[r], ty[r]
            for b in range(n):
                to[t + o * b] += w * source[b]


@numba.njit(cache=True, nogil=True)
def _shifted_laplacian(x, scale, shift, out):  # pragma: no cover (jit)
    """``out = scale (x[i-1, j] + x[i+1, j] + x[i, j-1] + x[i, j+1] - 4 x) - shift x``, periodic."""
    n = x.shape[0]
    for i in range(n):
        row, up, down, to = x[i], x[(i - 1) % n], x[(i + 1) % n], out[i]
        to[0] = scale * (up[0] + down[0] + row[n - 1] + row[1] - 4 * row[0]) - shift * row[0]
        for j in range(1, n - 1):
            to[j] = scale * (up[j] + down[j] + row[j - 1] + row[j + 1] - 4 * row[j]) - shift * row[j]
        to[n - 1] = scale * (up[n - 1] + down[n - 1] + row[n - 2] + row[0] - 4 * row[n - 1]) - shift * row[n - 1]


@numba.njit(cache=True, nogil=True)
def biharmonic(layers, scales, shifts, weights, out):  # pragma: no cover (jit)
    """``out[l] = w_l L_l L_l layers[l]``, ``L_l x = scales[l] Lap x - shifts[l] x`` with ``Lap``
    the periodic 5-point stencil (:func:`_shifted_laplacian` twice)."""
    inner = np.empty(layers.shape[1:], dtype=layers.dtype)
    for layer in range(layers.shape[0]):
        _shifted_laplacian(layers[layer], scales[layer], shifts[layer], inner)
        _shifted_laplacian(inner, scales[layer], shifts[layer], out[layer])
        target = out[layer]
        weight = weights[layer]
        for i in range(target.shape[0]):
            row = target[i]
            for j in range(row.shape[0]):
                row[j] *= weight


@numba.njit(cache=True, nogil=True)
def couple_layers(pairs, blocks, spectrum, out):  # pragma: no cover (jit)
    """``out[l, i, j] = sum_k B_lk[i, j] spectrum[k, i, j]`` for a Hermitian ``n_layers x
    n_layers`` matrix ``B`` per frequency, given by its upper triangle: ``blocks[p] = B_lk``
    (n_pairs, n, n//2+1) for ``(l, k) = pairs[p]``, ``l <= k``; ``B_kl = conj(B_lk)``."""
    for i in range(spectrum.shape[1]):
        out[:, i] = 0
        for p in range(pairs.shape[0]):
            layer, k = pairs[p, 0], pairs[p, 1]
            block, to, values = blocks[p, i], out[layer, i], spectrum[k, i]
            for j in range(to.shape[0]):
                to[j] += block[j] * values[j]
            if k != layer:
                to, values = out[k, i], spectrum[layer, i]
                for j in range(to.shape[0]):
                    to[j] += block[j].conjugate() * values[j]


LANES = 8
"""Partial sums of the dot products: independent additions the CPU overlaps (one running sum
waits for each addition), combined in a fixed order, so the same sums on every machine."""


@numba.njit(cache=True, nogil=True)
def _combined(partial):  # pragma: no cover (jit)
    total = 0.0
    for lane in range(LANES):
        total += partial[lane]
    return total


@numba.njit(cache=True, nogil=True)
def dot(a, b):  # pragma: no cover (jit)
    """``sum a b`` of flat arrays, accumulated in float64 (:data:`LANES` partial sums)."""
    partial = np.zeros(LANES)
    body = a.shape[0] - a.shape[0] % LANES
    for k in range(0, body, LANES):
        for lane in range(LANES):
            partial[lane] += np.float64(a[k + lane]) * np.float64(b[k + lane])
    for k in range(body, a.shape[0]):
        partial[0] += np.float64(a[k]) * np.float64(b[k])
    return _combined(partial)


@numba.njit(cache=True, nogil=True)
def advance(x, r, p, ap, alpha):  # pragma: no cover (jit)
    """PCG's step of flat arrays: ``x += alpha p``, ``r -= alpha ap`` (``alpha`` in their dtype);
    returns ``|r|^2`` (float64, as :func:`dot`)."""
    partial = np.zeros(LANES)
    body = x.shape[0] - x.shape[0] % LANES
    for k in range(0, body, LANES):
        for lane in range(LANES):
            x[k + lane] += alpha * p[k + lane]
            r[k + lane] -= alpha * ap[k + lane]
            partial[lane] += np.float64(r[k + lane]) * np.float64(r[k + lane])
    for k in range(body, x.shape[0]):
        x[k] += alpha * p[k]
        r[k] -= alpha * ap[k]
        partial[0] += np.float64(r[k]) * np.float64(r[k])
    return _combined(partial)


@numba.njit(cache=True, nogil=True)
def new_direction(p, z, beta):  # pragma: no cover (jit)
    """PCG's next direction of flat arrays: ``p = z + beta p`` (``beta`` in their dtype)."""
    for k in range(p.shape[0]):
        p[k] = z[k] + beta * p[k]
