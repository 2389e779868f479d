"""Compiled detector noise of lucky imaging: keyed random streams, photon and read noise with
the per-frame sums fused (:mod:`.detector` drives them).

Random streams (:func:`detect_frames`): every frame has its own, keyed by
``(seed, key, frame index)`` through splitmix64 (Steele, Lea & Flood 2014) into the
states of xoshiro256++ generators (Blackman & Vigna 2021): ``LANES`` interleaved
ones for the Gaussian read noise (stepped as one vector) and one for the rest
(photons, the ziggurat's rare slow path). A frame's draws therefore depend on the
seed, the detector's key and the frame's index only: not on the chunking, the other
frames or the other detectors.

Gaussian deviates: the ziggurat method (Marsaglia & Tsang 2000) with 256 layers and
23-bit magnitudes in float32, numpy's ``standard_normal(dtype=float32)`` algorithm:
the rectangle test runs for 16 pixels at once (:mod:`.stream_vectors`), the rare rest
(wedges and the tail) per deviate.

Poisson photon counts, exact, in one of two ways (both are the same Poisson process):
few photons (``N sum I < n^2 / SEARCH_PER_PIXEL``): the total ``K ~ Poisson(N sum I)``,
each photon placed by inverse-CDF search on the frame's cumulative sum (float64);
otherwise pixel by pixel: ``Poisson(lambda)`` drawn directly where ``lambda = N I >=
BRIGHT`` (inversion below 10, Hörmann's PTRS above), and the other pixels laid end to
end on a line where the photons are the arrivals of a unit-rate Poisson process
(exponential gaps), so a pixel of mean ``lambda`` gets ``Poisson(lambda)`` independently
of the others (a Poisson process on disjoint intervals).
"""

import math

import numba
import numpy as np

from ..simd import fmuladd
from .stream_vectors import DEVIATES, GENERATORS, xoshiro_fill, ziggurat_rectangle

# numba's disk cache keys a kernel by its own file: this digest of the intrinsics the kernels
# inline makes an edit of theirs recompile them (tests/test_simd.py keeps it current)
# intrinsics digest (lucky/stream_vectors.py, simd.py): 51adaa151f16311a

LANES = GENERATORS
"""Interleaved xoshiro256++ generators of the Gaussian deviates (one vector)."""

SEARCH_PER_PIXEL = 10
"""Photons are placed by search when a frame expects fewer than n^2 / this (a search
costs ~10 times a pixel of the pixel-by-pixel way)."""

BRIGHT = 1.0
"""Pixels of mean >= this get their own Poisson draw (in the pixel-by-pixel way)."""

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_FALLBACK = np.uint64(4 * LANES)  # splitmix index of the scalar generator's state


def _ziggurat_tables():
    """256-layer ziggurat for float32 with 23-bit magnitudes: ``(k, w, f)``: accept
    ``m < k[i]``, deviate ``m w[i]``, ``f[i] = exp(-x_i^2 / 2)`` (Marsaglia & Tsang 2000)."""
    m1 = 2.0**23
    dn = tn = 3.6541528853610088
    vn = 4.92867323399e-3
    k, w, f = np.zeros(256, np.uint32), np.zeros(256), np.zeros(256)
    q = vn / math.exp(-0.5 * dn * dn)
    k[0], k[1] = int(dn / q * m1), 0
    w[0], w[255] = q / m1, dn / m1
    f[0], f[255] = 1.0, math.exp(-0.5 * dn * dn)
    for i in range(254, 0, -1):
        dn = math.sqrt(-2.0 * math.log(vn / dn + math.exp(-0.5 * dn * dn)))
        k[i + 1] = int(dn / tn * m1)
        tn = dn
        f[i] = math.exp(-0.5 * dn * dn)
        w[i] = dn / m1
    return k, w.astype(np.float32), f.astype(np.float32)


_ZK, _ZW, _ZF = _ziggurat_tables()
_ZK32 = _ZK.astype(np.int32)  # < 2^23
_ZR = np.float64(3.6541528853610088)  # the tail's start


@numba.njit(inline="always")
def _mix(z):  # pragma: no cover (jit)
    """splitmix64's output function of ``z + golden``."""
    z = z + _GOLDEN
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    return z ^ (z >> np.uint64(31))


@numba.njit(inline="always")
def _rotl(x, k):  # pragma: no cover (jit)
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@numba.njit(cache=True, nogil=True)
def stream_key(seed, key, frame):  # pragma: no cover (jit)
    """The 64-bit key of a frame's streams from (seed, key, frame index), each < 2^63."""
    return _mix(_mix(_mix(np.uint64(seed)) ^ np.uint64(key)) ^ np.uint64(frame))


@numba.njit(cache=True, nogil=True)
def _seed(h, lanes, scalar):  # pragma: no cover (jit)
    """States (4, LANES) and (4,) from the 64-bit key ``h`` (splitmix64 sequence)."""
    for j in range(4):
        for lane in range(LANES):
            lanes[j, lane] = _mix(h + np.uint64(j * LANES + lane) * _GOLDEN)
        scalar[j] = _mix(h + (_FALLBACK + np.uint64(j)) * _GOLDEN)


@numba.njit(inline="always")
def _xoshiro(a, b, c, d):  # pragma: no cover (jit)
    """One xoshiro256++ step of the state (a, b, c, d): (output, new a, b, c, d)."""
    out = _rotl(a + d, 23) + a
    t = b << np.uint64(17)
    c ^= a
    d ^= b
    b ^= c
    a ^= d
    c ^= t
    return out, a, b, c, _rotl(d, 45)


@numba.njit(inline="always")
def _next(s):  # pragma: no cover (jit)
    """xoshiro256++ step of the scalar state ``s`` (4,): a uint64."""
    out, s[0], s[1], s[2], s[3] = _xoshiro(s[0], s[1], s[2], s[3])
    return out


@numba.njit(inline="always")
def _uniform(s):  # pragma: no cover (jit)
    """Uniform float64 in (0, 1): 53 bits, offset by half a step."""
    return (np.float64(_next(s) >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, nogil=True)
def _fill_bits(lanes, out):  # pragma: no cover (jit)
    """``out`` (m,) uint64, m a multiple of LANES, from the interleaved generators ``lanes`` (4, LANES)
    (value ``i`` from generator ``i % LANES``; one vector step, :func:`.stream_vectors.xoshiro_fill`)."""
    xoshiro_fill(lanes, out)


@numba.njit(inline="always")
def _normal_slow(idx, x, s):  # pragma: no cover (jit)
    """The ziggurat after a failed rectangle test of layer ``idx`` with deviate ``x``:
    the wedge or tail test with fresh uniforms of ``s``, then, if rejected, new tries."""
    idx = np.int64(idx)
    while True:
        if idx == 0:  # the tail beyond r (Marsaglia 1964)
            while True:
                xx = -math.log(_uniform(s)) / _ZR
                yy = -math.log(_uniform(s))
                if yy + yy > xx * xx:
                    return np.float32(-(_ZR + xx) if x < 0 else _ZR + xx)
        fx = np.float64(_ZF[idx]) + _uniform(s) * (np.float64(_ZF[idx - 1]) - np.float64(_ZF[idx]))
        if fx < math.exp(-0.5 * np.float64(x) * np.float64(x)):
            return x
        while True:  # a new try
            r = np.int64(_next(s) >> np.uint64(32))
            idx = r & 0xFF
            m = (r >> 9) & 0x7FFFFF
            x = np.float32(m) * _ZW[idx]
            if (r >> 8) & 1:
                x = -x
            if m < _ZK32[idx]:
                return x
            break


@numba.njit(cache=True, nogil=True)
def _normals(words, out, s):  # pragma: no cover (jit)
    """Standard normal float32 ``out`` (m,) from 32-bit words ``words`` (m,) int32, m a multiple of
    16: bits 0-7 the layer, 8 the sign, 9-31 the magnitude; the rectangle test 16 at a time
    (:func:`.stream_vectors.ziggurat_rectangle`: ~1.5% fail it), the rest per deviate, in order, with
    the generator ``s`` (:func:`_normal_slow`, inlined: no fast-math flags here or there)."""
    for start in range(0, out.size, DEVIATES):
        failed = ziggurat_rectangle(words, start, _ZW, _ZK32, out)
        while failed:  # each set bit, lowest first
            k = 0
            while not (failed >> k) & 1:
                k += 1
            failed &= failed - 1
            out[start + k] = _normal_slow(words[start + k] & 0xFF, out[start + k], s)


@numba.njit(cache=True, nogil=True)
def _poisson(lam, s):  # pragma: no cover (jit)
    """Poisson(lam) deviate: inversion below 10, PTRS (Hörmann 1993) above (as numpy)."""
    if lam < 10.0:
        p = math.exp(-lam)
        u = _uniform(s)
        k = 0
        cdf = p
        while u > cdf and p > 0.0:
            k += 1
            p *= lam / k
            cdf += p
        return k
    slam = math.sqrt(lam)
    loglam = math.log(lam)
    b = 0.931 + 2.53 * slam
    a = -0.059 + 0.02483 * b
    invalpha = 1.1239 + 1.1328 / (b - 3.4)
    vr = 0.9277 - 3.6224 / (b - 2.0)
    while True:
        u = _uniform(s) - 0.5
        v = _uniform(s)
        us = 0.5 - abs(u)
        k = math.floor((2.0 * a / us + b) * u + lam + 0.43)
        if us >= 0.07 and v <= vr:
            return int(k)
        if k < 0 or (us < 0.013 and v > us):
            continue
        if math.log(v) + math.log(invalpha) - math.log(a / (us * us) + b) <= -lam + k * loglam - math.lgamma(k + 1.0):
            return int(k)


@numba.njit(cache=True, nogil=True)
def cumulative(unit, within, rows):  # pragma: no cover (jit)
    """Cumulative sums of the positive pixels of frames ``unit`` (k, n, n), float64: along
    each row, ``within`` (k, n, n), and of the row totals, ``rows`` (k, n). Four rows at a
    time (independent sums)."""
    k, n, _ = unit.shape
    for j in range(k):
        for y0 in range(0, n - n % 4, 4):
            a0 = a1 = a2 = a3 = 0.0
            for x in range(n):
                a0 += max(np.float64(unit[j, y0, x]), 0.0)
                a1 += max(np.float64(unit[j, y0 + 1, x]), 0.0)
                a2 += max(np.float64(unit[j, y0 + 2, x]), 0.0)
                a3 += max(np.float64(unit[j, y0 + 3, x]), 0.0)
                within[j, y0, x], within[j, y0 + 1, x] = a0, a1
                within[j, y0 + 2, x], within[j, y0 + 3, x] = a2, a3
        for y in range(n - n % 4, n):
            a = 0.0
            for x in range(n):
                a += max(np.float64(unit[j, y, x]), 0.0)
                within[j, y, x] = a
        total = 0.0
        for y in range(n):
            total += within[j, y, n - 1]
            rows[j, y] = total


@numba.njit(inline="always")
def _first_above(cumulative, u):  # pragma: no cover (jit)
    """First index whose value in the non-decreasing ``cumulative`` exceeds ``u`` (bisection;
    the last index if none)."""
    lo, hi = 0, cumulative.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        if cumulative[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    return lo


@numba.njit(cache=True, nogil=True)
def _place(within, rows, photons, out, s):  # pragma: no cover (jit)
    """Add Poisson counts of means ``photons I`` to ``out`` (n, n), ``I`` the frame of the
    cumulative sums ``within`` (n, n) and ``rows`` (n,) (:func:`cumulative`): ``K ~
    Poisson(photons sum I)`` photons, each at the first row whose cumulative total exceeds
    ``u sum I``, then the first pixel of it whose cumulative sum exceeds the rest (the last
    positive one if rounding leaves none)."""
    n = within.shape[0]
    total = rows[n - 1]
    if not total > 0:
        return
    top = np.nextafter(total, 0.0)
    for _ in range(_poisson(photons * total, s)):
        u = min(_uniform(s) * total, top)
        y = _first_above(rows, u)
        if y > 0:
            u -= rows[y - 1]
        row = within[y]
        lo = _first_above(row, u)
        while lo > 0 and row[lo] == row[lo - 1]:
            lo -= 1  # only if rounding left u at the row's end: back to a positive pixel
        out[y, lo] += 1.0


@numba.njit(cache=True, nogil=True)
def _per_pixel(unit, photons, out, s):  # pragma: no cover (jit)
    """Add Poisson counts of means ``photons unit`` (n, n) to ``out`` pixel by pixel:
    own draws where the mean is >= BRIGHT, unit-rate arrivals along the others."""
    n = unit.shape[0]
    gap = -math.log(_uniform(s))  # to the next arrival
    for y in range(n):
        for x in range(n):
            v = unit[y, x]
            if not v > 0:
                continue
            lam = photons * np.float64(v)
            if lam >= BRIGHT:
                out[y, x] += _poisson(lam, s)
                continue
            if gap > lam:
                gap -= lam
                continue
            count = 0
            while gap <= lam:
                lam -= gap
                count += 1
                gap = -math.log(_uniform(s))
            gap -= lam
            out[y, x] += count


@numba.njit(inline="always")
def _finish(out, normals, sigma, rows, cols):  # pragma: no cover (jit)
    """``out += sigma normals`` (if sigma > 0; fused multiply-adds), then the row and column sums
    (float64, each in the order of its pixels: the rows eight side by side, independent sums that
    hide each other's latency) and the peak of the frame ``out`` (n, n) (finite values). No fast-math
    flags: the same operations inlined anywhere."""
    n = out.shape[0]
    high = np.full(n, -np.inf, np.float32)
    cols[:] = 0.0
    for y in range(n):  # vectorised over the columns
        o, g = out[y], normals[y * n : (y + 1) * n]
        for x in range(n):
            v = fmuladd(sigma, g[x], o[x]) if sigma > 0 else o[x]
            o[x] = v
            cols[x] += np.float64(v)
            if v > high[x]:
                high[x] = v
    whole = n - n % 8
    for y0 in range(0, whole, 8):
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 0.0
        for x in range(n):
            a0 += np.float64(out[y0, x])
            a1 += np.float64(out[y0 + 1, x])
            a2 += np.float64(out[y0 + 2, x])
            a3 += np.float64(out[y0 + 3, x])
            a4 += np.float64(out[y0 + 4, x])
            a5 += np.float64(out[y0 + 5, x])
            a6 += np.float64(out[y0 + 6, x])
            a7 += np.float64(out[y0 + 7, x])
        rows[y0], rows[y0 + 1], rows[y0 + 2], rows[y0 + 3] = a0, a1, a2, a3
        rows[y0 + 4], rows[y0 + 5], rows[y0 + 6], rows[y0 + 7] = a4, a5, a6, a7
    for y in range(whole, n):
        a = 0.0
        for x in range(n):
            a += np.float64(out[y, x])
        rows[y] = a
    return high.max()


@numba.njit(cache=True, nogil=True)
def frame_sums(frames, rows, cols, peak):  # pragma: no cover (jit)
    """Row and column sums ``rows``, ``cols`` (k, n) float64 and peaks ``peak`` (k,) of frames
    (k, n, n) float32, as :func:`detect_frames` gives them for the frames it draws."""
    for j in range(frames.shape[0]):
        peak[j] = _finish(frames[j], frames[j, 0], np.float32(0.0), rows[j], cols[j])  # sigma 0: reads only


@numba.njit(cache=True, nogil=True)
def detect_frames(
    unit, within, row_cumulative, photons, sigma, seed, key, first_frame, drawn, out, rows, cols, peak, bits, normals
):  # pragma: no cover (jit)
    """Detected frames ``out`` (k, n, n) float32 of unit-flux frames ``unit`` (k, n, n)
    (negative values count as 0) of cumulative sums ``within``, ``row_cumulative``
    (:func:`cumulative`), photons per frame ``photons``, read noise ``sigma`` (float32):
    frame ``j``'s streams are keyed by (seed, key, first_frame + j). Also per frame: row
    and column sums ``rows``, ``cols`` (k, n) float64 and the peak ``peak`` (k,). Only the
    frames ``j`` with ``drawn[j]`` (k,) bool are drawn (the others' outputs untouched).
    Work arrays: ``bits`` (n^2 / 2,) uint64, ``normals`` (n^2,) float32."""
    k, n, _ = unit.shape
    lanes = np.empty((4, LANES), np.uint64)
    s = np.empty(4, np.uint64)
    words = bits.view(np.int32)
    for j in range(k):
        if not drawn[j]:
            continue
        _seed(stream_key(seed, key, first_frame + j), lanes, s)
        frame = out[j]
        frame[:] = 0.0
        if sigma > 0:
            _fill_bits(lanes, bits)
            _normals(words, normals, s)
        if photons * row_cumulative[j, n - 1] < n * n / SEARCH_PER_PIXEL:
            _place(within[j], row_cumulative[j], photons, frame, s)
        else:
            _per_pixel(unit[j], photons, frame, s)
        peak[j] = _finish(frame, normals, sigma, rows[j], cols[j])
