"""Compiled Shack-Hartmann exposure: spectra of sub-aperture intensities, spot
OTFs and pixel integration for all sub-apertures of all beacons in one call.

Model: :func:`luckyao.wfs.shack_hartmann.exposure_images`. The Fourier coefficients of the
summed intensities ``sum_t |DFT_N(f_t)|^2`` are the field autocorrelations
(Wiener-Khinchin; Goodman, *Fourier Optics*, sec. 6.3)
``C[q, p] = N^2 sum_t sum_{y,x} f_t[y - q, x - p] conj f_t[y, x]``, evaluated in
mixed form (``G_t = DFT_N`` along y of the zero-padded field, N >= 2 n_in):

1. ``H[ky, p] = sum_t sum_x G_t[ky, x - p] conj G_t[ky, x]`` (x autocorrelation);
2. ``C[q, p] = N sum_ky H[ky, p] exp(-2 pi i ky q / N)``;

for the half plane ``0 <= p < n_lags``, ``|q| < n_lags`` only: ``n_lags = n_in``
holds every non-zero coefficient; with an uplink spot, whose OTF is the same
autocorrelation of the launch field, zero beyond ``n_launch``, ``n_lags`` is
at most ``n_launch``. Then ``D = C x elongation x uplink`` and the pixels
``P[j, k] = Re sum_{q,p} E_y[j, q] D[q, p] E_x[k, p]``.

Layout: a chunk of ``lanes`` fields (sub-apertures of one beacon, or the
exposure's launch fields) is stored innermost, so that every statement is a
SIMD loop over lanes. The DFTs, the autocorrelation and the pixel sums are
straight-line code generated per size (:mod:`luckyao.wfs.codelets`, cached
in the package's ``__pycache__``); the rest is plain numba, with small per-size drivers.
"""

import hashlib
import inspect
from functools import cache
from pathlib import Path

import numba
import numpy as np

from ..optics.sincos import SINCOS_DIGEST
from ..simd import LANES, transpose
from . import drivers
from .codelets import Codelet, dft, load_module, term_value

# numba's disk cache keys a kernel by its own file: this digest of the intrinsics the kernels
# inline makes an edit of theirs recompile them (tests/test_simd.py keeps it current)
# intrinsics digest (simd.py): 86b3bc4b14f3bbee

_U = numba.uint64  # unsigned offsets keep the lane loops vectorisable
_FASTMATH = {"contract"}  # fused multiply-adds; no reassociation
_LAG_GROUP = 8  # lags accumulated together in registers by the autocorrelation


# --- generated straight-line kernels ---------------------------------------------
# Complex arrays are one float32 array, real parts then imaginary parts: few
# distinct arrays keep LLVM's run-time alias checks, hence vectorisation, possible.
def _stored(codelet: Codelet, values, array: str, offset: str, stride: int, im_offset: int) -> list[str]:
    """Lines computing the codelet's complex ``values`` and storing value ``i`` at
    ``array[offset + i stride]`` (real part) and ``+ im_offset`` (imaginary part)."""
    lines = codelet.source([t for v in values for t in v], " " * 12)
    for i, (re, im) in enumerate(values):
        lines += [
            f"            {array}[{offset} + {i * stride}] = {term_value(re)}",
            f"            {array}[{offset} + {im_offset + i * stride}] = {term_value(im)}",
        ]
    return lines


def _columns_source(n_fft: int, n_in: int, lanes: int) -> tuple[list[str], dict]:
    """Fields and their y DFTs ``g[x, ky, l] = sum_{y < n_in} f[x, y, l] exp(-2 pi i ky y / N)``,
    ``f = amp exp(i ratio phi)`` with ``amp``, ``phi`` (x, y, L) (pruned DFT)."""
    codelet = Codelet()
    field = [(codelet.input(f"fr{y}"), codelet.input(f"fi{y}")) if y < n_in else (None, None) for y in range(n_fft)]
    spectrum = dft(codelet, field)
    im = n_in * n_fft * lanes
    lines = [
        "def columns(phi, ratio, amp, g):",
        f"    for x in range({n_in}):",
        f"        for lane in range({lanes}):",
        f"            o = _U(x * {n_in * lanes} + lane)",
        f"            og = _U(x * {n_fft * lanes} + lane)",
    ]
    for y in range(n_in):
        lines += [
            f"            c{y}, s{y} = sincos(phi[o + {y * lanes}] * ratio)",
            f"            fr{y} = amp[o + {y * lanes}] * c{y}",
            f"            fi{y} = amp[o + {y * lanes}] * s{y}",
        ]
    return lines + _stored(codelet, spectrum, "g", "og", lanes, im), codelet.constants


def _correlate_source(n_fft: int, n_in: int, lanes: int, n_lags: int) -> tuple[list[str], dict]:
    """``h[ky, p, l] (+)= sum_x g[x - p, ky, l] conj g[x, ky, l]`` for ``p < n_lags``
    (``+=`` if ``accumulate``, else ``=``).

        Lags go in groups of ``_LAG_GROUP`` whose sums stay in registers; each
        group reloads ``g`` (it follows stores to ``h``), which keeps the register
        pressure low.
    """
    column, g_im, h_im = n_fft * lanes, n_in * n_fft * lanes, n_fft * n_lags * lanes
    lines = [
        "def correlate(g, h, accumulate):",
        "    zero = np.float32(0.0)",
        f"    for ky in range({n_fft}):",
        f"        for lane in range({lanes}):",
        f"            o = _U(ky * {lanes} + lane)",
        f"            oh = _U(ky * {n_lags * lanes} + lane)",
    ]
    for first in range(0, n_lags, _LAG_GROUP):
        lags = range(first, min(first + _LAG_GROUP, n_lags))
        sums = {p: (f"sr{p}_0", f"si{p}_0") for p in lags}
        for p in lags:
            lines.append(f"            sr{p}_0 = h[oh + {p * lanes}] if accumulate else zero")
            if p:
                lines.append(f"            si{p}_0 = h[oh + {h_im + p * lanes}] if accumulate else zero")
        loaded = set()
        for x in range(first, n_in):
            for x_load in [x] + [x - p for p in lags if p <= x]:
                if x_load not in loaded:
                    loaded.add(x_load)
                    lines += [
                        f"            r{x_load}_{first} = g[o + {x_load * column}]",
                        f"            i{x_load}_{first} = g[o + {g_im + x_load * column}]",
                    ]
            for p in [p for p in lags if p <= x]:
                a, b = f"{x - p}_{first}", f"{x}_{first}"
                re, im = sums[p]
                sums[p] = (f"sr{p}_{x + 1}", "zero" if p == 0 else f"si{p}_{x + 1}")
                lines.append(f"            {sums[p][0]} = {re} + r{a} * r{b} + i{a} * i{b}")
                if p:  # lag 0: sum |g|^2, real
                    lines.append(f"            {sums[p][1]} = {im} + i{a} * r{b} - r{a} * i{b}")
        for p in lags:
            lines += [
                f"            h[oh + {p * lanes}] = {sums[p][0]}",
                f"            h[oh + {h_im + p * lanes}] = {sums[p][1]}",
            ]
    return lines, {}


def _spectrum_source(n_fft: int, lanes: int, n_lags: int) -> tuple[list[str], dict]:
    """``c[q + n_lags - 1, p, l] = sum_ky h[ky, p, l] exp(-2 pi i ky q / N)``, ``|q| < n_lags``
    (the DFT pruned to those outputs)."""
    codelet = Codelet()
    rows = [(codelet.input(f"hr{k}"), codelet.input(f"hi{k}")) for k in range(n_fft)]
    spectrum = dft(codelet, rows)
    wanted = [spectrum[q % n_fft] for q in range(1 - n_lags, n_lags)]
    row, h_im, c_im = n_lags * lanes, n_fft * n_lags * lanes, len(wanted) * n_lags * lanes
    lines = [
        "def spectrum(h, c):",
        f"    for p in range({n_lags}):",
        f"        for lane in range({lanes}):",
        f"            o = _U(p * {lanes} + lane)",
    ]
    for k in range(n_fft):
        lines += [f"            hr{k} = h[o + {k * row}]", f"            hi{k} = h[o + {h_im + k * row}]"]
    return lines + _stored(codelet, wanted, "c", "o", row, c_im), codelet.constants


def _pixels_source(lanes: int, n_lags: int, n_pix: int) -> tuple[list[str], dict]:
    """Pixels ``out[j, k, l] = Re sum_{q,p} K[j, q, p] el[q, p, l] c[q, p, l] E_x[k, p]``;
    ``c``, ``el`` (n_q, n_lags, L); ``w`` = ``K`` (n_pix, n_q, n_lags) then ``E_x``
    (n_pix, n_lags). ``r[j] = sum_q K el c`` accumulates in a small buffer.

    The weights are read before each lane loop: loads inside it would each
    need a run-time alias check, which stops vectorisation.
    """
    n_q = 2 * n_lags - 1
    c_im, r_im = n_q * n_lags * lanes, n_pix * lanes
    w_im = n_pix * (n_q + 1) * n_lags
    lines = [
        "def pixels(c, el, w, out):",
        f"    r = np.empty({2 * r_im}, np.float32)",
        "    out[:] = 0.0",
        f"    for p in range({n_lags}):",
        "        r[:] = 0.0",
        f"        for q in range({n_q}):",
        f"            k = q * {n_lags} + p",
    ]
    lines += [f"            kr{j} = w[k + {j * n_q * n_lags}]" for j in range(n_pix)]
    lines += [f"            ki{j} = w[k + {w_im + j * n_q * n_lags}]" for j in range(n_pix)]
    lines += [
        f"            for lane in range({lanes}):",
        f"                o = _U(k * {lanes} + lane)",
        "                cr = c[o]",
        f"                ci = c[o + {c_im}]",
        "                er = el[o]",
        f"                ei = el[o + {c_im}]",
        "                dr = cr * er - ci * ei",
        "                di = cr * ei + ci * er",
        "                i = _U(lane)",
    ]
    for j in range(n_pix):
        lines += [
            f"                r[i + {j * lanes}] += kr{j} * dr - ki{j} * di",
            f"                r[i + {r_im + j * lanes}] += kr{j} * di + ki{j} * dr",
        ]
    x = n_pix * n_q * n_lags
    lines += [f"        xr{k} = w[p + {x + k * n_lags}]" for k in range(n_pix)]
    lines += [f"        xi{k} = w[p + {w_im + x + k * n_lags}]" for k in range(n_pix)]
    lines += [f"        for lane in range({lanes}):", "            i = _U(lane)"]
    for j in range(n_pix):
        lines += [f"            rr = r[i + {j * lanes}]", f"            ri = r[i + {r_im + j * lanes}]"]
        lines += [f"            out[i + {(j * n_pix + k) * lanes}] += rr * xr{k} - ri * xi{k}" for k in range(n_pix)]
    return lines, {}


_SOURCES = {
    "columns": _columns_source,
    "correlate": _correlate_source,
    "pixels": _pixels_source,
    "spectrum": _spectrum_source,
}


@cache
def _generated(name: str, *size: int):
    """Compiled generated kernel ``name`` (a key of ``_SOURCES``) of one size."""
    source, constants = _SOURCES[name](*size)
    lines = ['"""Generated by luckyao.wfs.kernels; do not edit."""', "import numba", "import numpy as np"]
    if any("sincos(" in line for line in source):
        lines += [f"from luckyao.optics.sincos import sincos  # {SINCOS_DIGEST}"]
    lines += ["", "_U = numba.uint64"]
    lines += [f"{constant} = np.float32({float(value)!r})" for constant, value in constants.items()]
    lines += ["", "", f"@numba.njit(cache=True, nogil=True, fastmath={_FASTMATH!r})"] + source
    module = load_module("_".join(map(str, (name, *size))), "\n".join(lines) + "\n")
    return getattr(module, name)


# --- stages with run-time sizes -----------------------------------------------------
@numba.njit(cache=True, nogil=True)
def gather(phase, source, row_m, n_in, phi):  # pragma: no cover (jit)
    """phi[x, y, l] = phase[source[l] + y row_m + x]: a chunk's blocks, lanes innermost;
    16 lanes' rows of 16 x at a time, transposed in registers (:func:`luckyao.simd.transpose`)."""
    lanes = source.size
    for first in range(0, lanes, LANES):
        rows = min(LANES, lanes - first)
        for y in range(n_in):
            for x in range(0, n_in, LANES):
                transpose(
                    phase,
                    y * row_m + x,
                    source,
                    first,
                    rows,
                    min(LANES, n_in - x),
                    phi,
                    (x * n_in + y) * lanes + first,
                    n_in * lanes,
                )


@numba.njit(cache=True, nogil=True)
def lane_otf(otf, q_index, n_lags, lane_subaperture, out):  # pragma: no cover (jit)
    """out[a, :, q, p, l] = otf[v, q_index[q], p] (real parts, then imaginary parts) for
    ``v = lane_subaperture[a, l]`` and ``p < n_lags``; 0 on padding lanes (``v < 0``)."""
    n_amp, lanes = lane_subaperture.shape
    n_q = q_index.size
    out[:] = 0.0
    for a in range(n_amp):
        for lane in range(lanes):
            v = lane_subaperture[a, lane]
            if v >= 0:
                for q in range(n_q):
                    for p in range(n_lags):
                        z = otf[v, q_index[q], p]
                        out[a, 0, q, p, lane] = z.real
                        out[a, 1, q, p, lane] = z.imag


@numba.njit(cache=True, nogil=True)
def pixel_weights(spot, ey, ex, norm, w):  # pragma: no cover (jit)
    """w[b] = K (n_pix, n_q, n_lags) = norm E_y[j, q] spot[b, q, p], then E_x (n_pix, n_lags);
    real parts then imaginary parts."""
    n_b, n_q, n_lags = spot.shape
    n_pix = ey.shape[0]
    im = n_pix * (n_q + 1) * n_lags
    for b in range(n_b):
        o = b * 2 * im
        for j in range(n_pix):
            for q in range(n_q):
                er = ey[j, q].real * norm
                ei = ey[j, q].imag * norm
                for p in range(n_lags):
                    sr = spot[b, q, p].real
                    si = spot[b, q, p].imag
                    w[o + (j * n_q + q) * n_lags + p] = er * sr - ei * si
                    w[o + im + (j * n_q + q) * n_lags + p] = er * si + ei * sr
            for p in range(n_lags):
                w[o + (n_pix * n_q + j) * n_lags + p] = ex[j, p].real
                w[o + im + (n_pix * n_q + j) * n_lags + p] = ex[j, p].imag


@numba.njit(cache=True, nogil=True)
def centroids(images, x_rad, remove_tilt, out):  # pragma: no cover (jit)
    """out[b, :, v] = centre of gravity (x, y) [rad] of images[b, v] (0 without flux, NaN
    for a NaN or negative total), less its mean over v if ``remove_tilt``."""
    n_b, n_v, n_p = images.shape[0], images.shape[1], images.shape[2]
    for b in range(n_b):
        for v in range(n_v):
            flux = 0.0
            sx = 0.0
            sy = 0.0
            for j in range(n_p):
                for k in range(n_p):
                    w = images[b, v, j, k]
                    flux += w
                    sx += w * x_rad[k]
                    sy += w * x_rad[j]
            if flux > 0.0:
                out[b, 0, v] = sx / flux
                out[b, 1, v] = sy / flux
            elif flux == 0.0:  # no light (or read noise summing to nothing): no information
                out[b, 0, v] = 0.0
                out[b, 1, v] = 0.0
            else:  # NaN in the image, or a negative total from read noise: never a plausible number
                out[b, 0, v] = np.nan
                out[b, 1, v] = np.nan
        if remove_tilt:
            for axis in range(2):
                out[b, axis] -= out[b, axis].mean()


# --- per-size drivers ----------------------------------------------------------------
_KERNELS_DIGEST = hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]
"""Digest of this module's source, written into each generated driver: numba's disk cache
tracks only a function's own file, so an edit here must give the drivers new files."""


def _driver(template, size: tuple[int, ...], constants: dict[str, object], codelets: dict[str, tuple]):
    """``template`` (a function of :mod:`luckyao.wfs.drivers`) compiled with its free
    names bound to ``constants`` (name -> value or Python expression) and to the generated
    ``codelets`` (name -> :func:`_generated` arguments), in a generated module of one
    ``size`` that numba caches on disk (:func:`luckyao.wfs.codelets.load_module`)."""
    lines = [
        '"""Generated by luckyao.wfs.kernels; do not edit."""',
        "import numba",
        "import numpy as np",
        f"from luckyao.wfs.kernels import _generated, gather, pixel_weights  # {_KERNELS_DIGEST}",
        "",
    ]
    lines += [f"{name} = {value}" for name, value in constants.items()]
    lines += [
        f"{name} = _generated{arguments!r}  # {_generated(*arguments).py_func.__module__}"
        for name, arguments in codelets.items()
    ]
    lines += ["", "", "@numba.njit(cache=True, nogil=True)", inspect.getsource(template)]
    module = load_module("_".join(map(str, (template.__name__, *size))), "\n".join(lines))
    return getattr(module, template.__name__)


@cache
def exposure_kernel(n_fft: int, n_in: int, lanes: int, n_lags: int, n_pix: int):
    """Compiled ``exposure(...)`` (:func:`luckyao.wfs.drivers.exposure`) for ``n_in`` x
    ``n_in`` sub-apertures, DFTs of ``n_fft`` (power of 2, >= 2 n_in), chunks of ``lanes``
    and ``n_pix`` pixels."""
    n_q = 2 * n_lags - 1
    return _driver(
        drivers.exposure,
        (n_fft, n_in, lanes, n_lags, n_pix),
        {
            "n_fft": n_fft,
            "n_in": n_in,
            "lanes": lanes,
            "n_lags": n_lags,
            "n_pix": n_pix,
            "n_q": n_q,
            "size_w": 2 * n_pix * (n_q + 1) * n_lags,
        },
        {
            "columns": ("columns", n_fft, n_in, lanes),
            "correlate": ("correlate", n_fft, n_in, lanes, n_lags),
            "spectrum": ("spectrum", n_fft, lanes, n_lags),
            "pixels": ("pixels", lanes, n_lags, n_pix),
        },
    )


@cache
def uplink_kernel(n_fft: int, n_launch: int, n_steps: int, n_beacons: int, n_lags: int):
    """Compiled ``uplink_otf(...)`` (:func:`luckyao.wfs.drivers.uplink_otf`) for ``n_steps``
    x ``n_beacons`` launch fields of ``n_launch`` x ``n_launch`` samples (DFTs of ``n_fft``
    >= 2 n_launch), one lane each; ``lanes`` (>= 16, a multiple of 8, so that LLVM
    vectorises) with padding."""
    n_fields = n_steps * n_beacons
    lanes = max(16, -(-n_fields // 8) * 8)
    return _driver(
        drivers.uplink_otf,
        (n_fft, n_launch, n_steps, n_beacons, n_lags),
        {
            "n_fft": n_fft,
            "n_launch": n_launch,
            "n_steps": n_steps,
            "n_beacons": n_beacons,
            "n_lags": n_lags,
            "lanes": lanes,
            "n_q": 2 * n_lags - 1,
            "sources": f"(np.minimum(np.arange({lanes}), {n_fields - 1}) * {n_launch * n_launch}).astype(np.int32)",
        },
        {
            "columns": ("columns", n_fft, n_launch, lanes),
            "correlate": ("correlate", n_fft, n_launch, lanes, n_lags),
            "spectrum": ("spectrum", n_fft, lanes, n_lags),
        },
    )
