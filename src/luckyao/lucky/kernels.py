"""Compiled kernels of lucky imaging: keyed random streams, detector noise with the
per-frame sums fused, binned encircled energy and recentred accumulation.

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
# intrinsics digest (lucky/stream_vectors.py, simd.py): 1cbeaf29717897f1

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
        if (math.log(v) + math.log(invalpha) - math.log(a / (us * us) + b)
                <= -lam + k * loglam - math.lgamma(k + 1.0)):
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
        o, g = out[y], normals[y * n: (y + 1) * n]
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
def detect_frames(unit, within, row_cumulative, photons, sigma, seed, key, first_frame, drawn, out, rows, cols,
                  peak, bits, normals):  # pragma: no cover (jit)
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


@numba.njit(cache=True, nogil=True)
def add_recentred(frames, shifts, rows, partial, sign):  # pragma: no cover (jit)
    """``partial[r] += sign roll(frames[j], shifts[j])`` (float64) for every ``r = rows[j, c] >= 0``,
    ``sign`` 1.0 (add; the same sums bit for bit as without it) or -1.0 (take out).

    ``frames`` (k, n, n) float32, ``shifts`` (k, 2) int64 (y, x) with ``np.roll``
    semantics, ``rows`` (k, m) int64, ``partial`` (R, >= n^2) float64, image ``r`` in
    ``partial[r, :n^2]`` (row-major; a row length other than a power of two keeps the
    images' rows in distinct cache sets). Output-row major: the partial rows of a few image
    rows stay in cache over the chunk's frames, ``tile`` image rows at a time (a frame's
    rows read in runs). A rolled row is added as two slices indexed from 0 (loops that
    vectorise: an index ``x - s`` would need numba's negative-index check per element).
    """
    k, n, _ = frames.shape
    tile = 4
    for y0 in range(0, n, tile):
        for j in range(k):
            sx = shifts[j, 1] % n
            for y in range(y0, min(y0 + tile, n)):
                src = frames[j, (y - shifts[j, 0]) % n]
                body, head = src[:n - sx], src[n - sx:]  # to columns sx.. and ..sx
                o = y * n
                for c in range(rows.shape[1]):
                    r = rows[j, c]
                    if r < 0:
                        continue
                    to_body, to_head = partial[r, o + sx:o + n], partial[r, o:o + sx]
                    for x in range(n - sx):
                        to_body[x] += sign * body[x]
                    for x in range(sx):
                        to_head[x] += sign * head[x]


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
def add_rows(vectors, rows, partial, sign):  # pragma: no cover (jit)
    """``partial[r, :m] += sign vectors[j]`` (float64) for every ``r = rows[j, c] >= 0``;
    ``vectors`` (k, m) float64, ``rows`` (k, c) int64, ``partial`` (R, >= m) float64.

    Element-tile major: ``tile`` elements of every row the chunk's frames touch stay in cache
    while each frame in turn is added to them (a run's partial sums are far larger than the
    cache: 0.6 of the time frame by frame takes, at 11 rows a frame); each element still
    receives the frames in their order, so the sums are the same bit for bit.
    """
    k, m = vectors.shape
    tile = 512
    for x0 in range(0, m, tile):
        x1 = min(x0 + tile, m)
        for j in range(k):
            v = vectors[j, x0:x1]
            for c in range(rows.shape[1]):
                r = rows[j, c]
                if r < 0:
                    continue
                to = partial[r, x0:x1]
                for x in range(x1 - x0):
                    to[x] += sign * v[x]


@numba.njit(cache=True, nogil=True)
def add_frames(frames, total):  # pragma: no cover (jit)
    """``total += sum_j frames[j]`` (float64) of frames (k, n, n) float32."""
    k, n, _ = frames.shape
    for y in range(n):
        for j in range(k):
            src = frames[j, y]
            dst = total[y]
            for x in range(n):
                dst[x] += src[x]


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
