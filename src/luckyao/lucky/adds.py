"""Compiled adds of lucky imaging: frames and vectors added to the partial sums of their
selection bins (float64, each sum receiving the frames in their order).
"""

import numba


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
                body, head = src[: n - sx], src[n - sx :]  # to columns sx.. and ..sx
                o = y * n
                for c in range(rows.shape[1]):
                    r = rows[j, c]
                    if r < 0:
                        continue
                    to_body, to_head = partial[r, o + sx : o + n], partial[r, o : o + sx]
                    for x in range(n - sx):
                        to_body[x] += sign * body[x]
                    for x in range(sx):
                        to_head[x] += sign * head[x]


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
