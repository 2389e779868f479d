"""Geometric propagation through frozen-flow layers along lines of sight.

A ray from pupil point ``g`` [m] towards direction ``theta`` [rad] from a
source at height ``H`` crosses the layer at height ``h`` at
``(1 - h/H) g + theta h`` (cone effect; ``H = inf`` for a star). The phase
there is the layer's strip screen, moved by frozen flow (any sub-sample shift),
sampled by bilinear interpolation. The strips are sampled on the sky grid, so
the footprint of a regular pupil grid is a scaled, shifted axis-aligned grid
on each: the interpolation weights are separable and each grid line reads two
contiguous screen lines.
"""

import numba
import numpy as np

from ..atmosphere.screens import ScreenSet
from ..atmosphere.statistics import Layer
from ..geometry import LineOfSight, footprint_m, footprint_scale
from ..simd import LANES, fmuladd
from .pupil import PupilGrid
from .taps import column_taps, row_taps

# numba's disk cache keys a kernel by its own file: this digest of the intrinsics the kernels
# inline makes an edit of theirs recompile them (tests/test_simd.py keeps it current)
# intrinsics digest (optics/taps.py, simd.py): dfbccef9dd712a44

_U = numba.uint64  # unsigned indices: numba emits no negative-index wraparound code


@numba.njit(cache=True, fastmath={"contract"}, nogil=True)
def _sample_kernel(
    screens,
    starts,
    n_major,
    n_minor,
    skew,
    major_axis,
    flow,
    u0,
    w0,
    beta,
    steps,
    layer_scales,
    column_runs,
    column_ptr,
    column_codes,
    row_runs,
    row_ptr,
    out,
):  # pragma: no cover (jit)
    """out[s, d, y, x] = sum_l layer_scales[s, l] bilinear(screen_l at the footprint of grid
    point (y, x) along line of sight d at time step steps[s]).

    A frame's or an exposure's steps go in one call, so that each layer's
    footprints are read from memory once for all of them (they move by less
    than a sample per step).

    On layer ``l`` the grid is axis-aligned: grid line ``a`` along the strip's
    major axis lies at ``u = u0[d, l] - step flow[l, 0] + beta[d, l] a``
    [samples], point ``b`` on it at minor ``w = w0[d, l] - step flow[l, 1] +
    beta[d, l] b``. Lines are grid rows (y) when the major axis is y, else
    columns. Per line the two screen lines ``floor(u)`` and ``+1`` are
    contiguous: they are interpolated first (vectorised), into ``between``;
    then the minor taps and weights, shared by all lines, are applied
    (:mod:`luckyao.optics.taps`): along a row, LANES points at a time; across
    columns, one point of LANES columns at a time, so that the grid is read
    and written contiguously. Only the mask's samples are computed:
    ``runs[ptr[p]:ptr[p + 1]]`` are the (start, end, lines) runs of line pair
    ``p`` (lines 1: the first, 2: the second, 3: both; :func:`_pair_runs`),
    ``column_codes`` the same per grid point (:func:`_column_codes`).
    Footprints stay on the screens (checked by the caller), so every index is
    non-negative: indices are unsigned, which spares the wraparound code.
    Fast-math is contraction only: sums are associated as written.
    """
    n_steps, n_dir, n, _ = out.shape
    tap = np.empty(n, np.int32)  # gather indices
    weight = np.empty(n, np.float32)
    # between lines: a row pair's (rows 0, 1) or LANES columns'; taps reach beta (n - 1) + 2
    between = np.zeros((LANES, int(beta.max() * n) + 4), np.float32)
    out[:] = 0.0
    for l in range(starts.shape[0]):  # layer-major: footprints of one layer share cached screen lines
        rows = major_axis[l] == 1  # lines are rows (points along x), else columns
        runs, ptr = (row_runs, row_ptr) if rows else (column_runs, column_ptr)
        m, k, n_lines = n_minor[l], skew[l], n_major[l]
        for s in range(n_steps):
            scale = np.float32(layer_scales[s, l])
            for d in range(n_dir):
                grid = out[s, d].reshape(-1)
                u_first = u0[d, l] - steps[s] * flow[l, 0]
                w_first = w0[d, l] - steps[s] * flow[l, 1]
                first = np.floor(w_first)  # minor coordinates may be negative before the line offset
                for b in range(n):
                    w = w_first - first + beta[d, l] * b
                    j = np.uint64(w)
                    tap[b] = np.int32(j)
                    weight[b] = np.float32(w - j)
                start = starts[l] + np.int64(first)
                if rows:
                    for p in range(ptr.size - 1):
                        if ptr[p + 1] == ptr[p]:
                            continue
                        j_lo, j_hi = _tap_range(tap, runs, ptr, p)
                        for h in range(min(2, n - 2 * p)):  # along the major axis first
                            _between(
                                screens,
                                start,
                                m,
                                k,
                                n_lines,
                                u_first + beta[d, l] * (2 * p + h),
                                scale,
                                j_lo,
                                j_hi,
                                between[h],
                            )
                        for r in range(ptr[p], ptr[p + 1]):  # then the minor taps
                            lo, hi, lines = runs[r, 0], runs[r, 1], runs[r, 2]
                            for b in range(lo, hi, LANES):
                                row_taps(between, tap, weight, b, min(LANES, hi - b), lines, grid, 2 * p * n, n)
                else:
                    for x0 in range(0, n, LANES):
                        width = min(LANES, n - x0)
                        y_lo, y_hi = n, 0
                        for x in range(x0, x0 + width):  # along the major axis first
                            p = x // 2
                            if ptr[p + 1] == ptr[p]:
                                continue
                            y_lo, y_hi = min(y_lo, runs[ptr[p], 0]), max(y_hi, runs[ptr[p + 1] - 1, 1])
                            j_lo, j_hi = _tap_range(tap, runs, ptr, p)
                            _between(
                                screens,
                                start,
                                m,
                                k,
                                n_lines,
                                u_first + beta[d, l] * x,
                                scale,
                                j_lo,
                                j_hi,
                                between[x - x0],
                            )
                        for y in range(y_lo, y_hi):  # then the minor taps
                            column_taps(between, tap, weight, y, grid, y * n + x0, column_codes, width)


@numba.njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _tap_range(tap, runs, ptr, p):  # pragma: no cover (jit)
    """The between samples [j_lo, j_hi) that line pair ``p``'s runs read."""
    return _U(tap[runs[ptr[p], 0]]), _U(tap[runs[ptr[p + 1] - 1, 1] - 1]) + _U(2)


@numba.njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")
def _between(screens, start, m, k, n_lines, u, scale, j_lo, j_hi, line):  # pragma: no cover (jit)
    """line[j] = scale x (the strip interpolated at major coordinate ``u`` [samples], minor sample j)
    for j_lo <= j < j_hi: screen lines ``floor(u)`` and ``+1`` (of ``m`` samples, skewed by ``k``
    over ``n_lines``) from ``start``."""
    i = np.int64(u)
    f = np.float32(u - i)
    near = _U(start + i * m - (k * i) // n_lines)
    far = _U(start + (i + 1) * m - (k * (i + 1)) // n_lines)
    g_near = scale * (np.float32(1.0) - f)
    g_far = scale * f
    for j in range(j_lo, j_hi):
        line[j] = fmuladd(g_far, screens[far + j], g_near * screens[near + j])


@numba.njit(cache=True, nogil=True)
def _pack(grid, runs, ptr, packed):  # pragma: no cover (jit)
    """packed[d, k] = grid[d] at the k-th sample of the runs, row by row (the mask's order)."""
    for d in range(grid.shape[0]):
        k = 0
        for y in range(grid.shape[1]):
            for r in range(ptr[y], ptr[y + 1]):
                for x in range(runs[r, 0], runs[r, 1]):
                    packed[d, k] = grid[d, y, x]
                    k += 1


class Propagator:
    """Samples the summed layer phases on a pupil grid for several lines of sight.

    ``grid`` (centred on ``centre_xy_m`` [m] in the pupil) is sampled for each
    line of sight, where ``mask`` (n, n) is true (default: everywhere; zero
    elsewhere); ``screens`` holds the layers' strips.
    """

    def __init__(
        self,
        layers: list[Layer],
        screens: ScreenSet,
        lines_of_sight: list[LineOfSight],
        grid: PupilGrid,
        centre_xy_m=(0.0, 0.0),
        mask: np.ndarray | None = None,
    ):
        specs = screens.specs
        if len(specs) != len(layers):
            raise ValueError(f"{len(layers)} layers but {len(specs)} screens")
        self.grid = grid
        n = grid.n_pix
        mask = np.ones((n, n), bool) if mask is None else np.asarray(mask, bool)
        self._row_runs = _runs(mask)
        self._column_runs = _runs(mask.T)
        self._row_pairs = _pair_runs(mask)
        self._column_pairs = _pair_runs(mask.T)
        self._column_codes = _column_codes(mask)
        self._screens = screens.flat
        self._starts = screens.starts
        self._n_major = np.array([s.n_major for s in specs], dtype=np.int64)
        self._n_minor = np.array([s.n_minor for s in specs], dtype=np.int64)
        self._skew = np.array([s.skew for s in specs], dtype=np.int64)
        self._major_axis = np.array([s.major_axis for s in specs], dtype=np.int64)
        self._step = np.array([s.step_samples for s in specs])  # (layer, major/minor)
        self._grids = {}  # per number of steps, for sample_valid
        self.n_valid = int(mask.sum())
        shape = (len(lines_of_sight), len(layers))
        self._u0, self._w0, self._beta = np.empty(shape), np.empty(shape), np.empty(shape)
        self.n_steps_max = 2**62
        """Steps for which every footprint stays on its screen."""
        first = grid.coords_m[0]
        for d, los in enumerate(lines_of_sight):
            for l, (layer, spec) in enumerate(zip(layers, specs)):
                origin = np.array(footprint_m(centre_xy_m[0] + first, centre_xy_m[1] + first, layer.height_m, los))
                major = spec.major_axis
                self._u0[d, l] = (origin[major] - spec.origin_m[0]) / spec.dx_m
                self._w0[d, l] = (origin[1 - major] - spec.origin_m[1]) / spec.dx_m
                self._beta[d, l] = float(footprint_scale(layer.height_m, los.height_m)) * grid.dx_m / spec.dx_m
                runs = self._column_runs if major == 0 else self._row_runs
                self.n_steps_max = min(self.n_steps_max, self._steps_on_screen(spec, d, l, runs, layer))

    def _steps_on_screen(self, spec, d, l, runs, layer) -> int:
        """Steps before the footprint of (d, l) leaves its strip along the major axis;
        ValueError if it does not fit across (checked at the first and last step:
        the minor drift is linear up to whole-sample line offsets)."""
        bounds, ptr = runs
        used = np.flatnonzero(ptr[1:] > ptr[:-1])
        lo, hi = bounds[ptr[used], 0], bounds[ptr[used + 1] - 1, 1]
        u = self._u0[d, l] + self._beta[d, l] * used
        speed = self._step[l, 0]
        steps = 2**62
        if speed > 0:
            steps = int(np.floor(u.min() / speed)) + 1
        elif speed < 0:
            steps = int(np.floor((spec.n_major - 2 - u.max()) / -speed)) + 1
        for step in {0, min(steps, 2**40) - 1}:
            ui = np.floor(u - step * speed).astype(np.int64)
            w_lo = self._w0[d, l] + self._beta[d, l] * lo - step * self._step[l, 1]
            w_hi = self._w0[d, l] + self._beta[d, l] * (hi - 1) - step * self._step[l, 1]
            offsets = np.stack([spec.line_offset(ui), spec.line_offset(ui + 1)])  # per grid line
            if (
                ui.min() < 0
                or ui.max() + 1 >= spec.n_major
                or (np.floor(w_lo) - offsets.max(axis=0)).min() < 0
                or (np.floor(w_hi) + 1 - offsets.min(axis=0)).max() >= spec.n_minor
            ):
                raise ValueError(
                    f"footprint at height {layer.height_m} m leaves its screen: "
                    "raise turbulence.field_radius_arcsec or shorten the case"
                )
        return steps

    def sample(self, steps, layer_scales, out: np.ndarray | None = None) -> np.ndarray:
        """Phases (k, n_los, n, n) float32 on the grid at the k time ``steps``,
        into ``out`` if given; at step ``steps[i]`` layer ``l`` is weighted by
        ``layer_scales[i, l]`` (e.g. r0^-5/6 sqrt(Cn2 fraction): rad at 500 nm)."""
        steps = np.asarray(steps, dtype=np.int64).reshape(-1)
        scales = np.asarray(layer_scales, dtype=np.float32).reshape(len(steps), -1)
        bad = steps[(steps < 0) | (steps >= self.n_steps_max)]
        if bad.size:
            raise IndexError(f"step {bad[0]} outside the screens' {self.n_steps_max} steps")
        n_los, n = self._u0.shape[0], self.grid.n_pix
        if out is None:
            out = np.empty((len(steps), n_los, n, n), dtype=np.float32)
        elif out.shape != (len(steps), n_los, n, n) or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be C-contiguous float32 of shape {(len(steps), n_los, n, n)}")
        _sample_kernel(
            self._screens,
            self._starts,
            self._n_major,
            self._n_minor,
            self._skew,
            self._major_axis,
            self._step,
            self._u0,
            self._w0,
            self._beta,
            steps,
            scales,
            *self._column_pairs,
            self._column_codes,
            *self._row_pairs,
            out,
        )
        return out

    def sample_valid(self, steps, layer_scales, out: np.ndarray | None = None) -> np.ndarray:
        """Like :meth:`sample`, but only the mask's samples: (k, n_los, n_valid)
        float32 in the order of ``grid[:, mask]``."""
        k, n_los = len(np.atleast_1d(steps)), self._u0.shape[0]
        if out is None:
            out = np.empty((k, n_los, self.n_valid), dtype=np.float32)
        grid = self.sample(steps, layer_scales, out=self._grid(k))
        _pack(grid.reshape(k * n_los, *grid.shape[2:]), *self._row_runs, out.reshape(k * n_los, -1))
        return out

    def _grid(self, k: int) -> np.ndarray:
        """The (k, n_los, n, n) grid behind :meth:`sample_valid` for k steps."""
        if k not in self._grids:
            self._grids[k] = np.empty((k, self._u0.shape[0], self.grid.n_pix, self.grid.n_pix), dtype=np.float32)
        return self._grids[k]


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs of true samples of each row of ``mask``: ``(runs, ptr)``, with row
    ``a``'s (start, end, 1) in ``runs[ptr[a]:ptr[a + 1]]``."""
    return _code_runs(mask.astype(np.int8))


def _pair_runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs of the row pairs (2p, 2p + 1) of ``mask``: ``(runs, ptr)``, with pair
    ``p``'s (start, end, lines) in ``runs[ptr[p]:ptr[p + 1]]``; ``lines`` is 1
    where only row 2p is true, 2 where only row 2p + 1 is, 3 where both are."""
    rows = np.pad(mask.astype(np.int8), ((0, mask.shape[0] % 2), (0, 0)))
    return _code_runs(rows[0::2] + 2 * rows[1::2])


def _column_codes(mask: np.ndarray) -> np.ndarray:
    """Flat int8 code of each grid point, its column pair's ``lines`` (:func:`_pair_runs` of
    ``mask.T``) seen from its own column: 3 where the point and its neighbour in the pair
    (column ``x ^ 1``) are true, 1 where only the point is, 0 where it is false."""
    n = mask.shape[1]
    padded = np.pad(mask, ((0, 0), (0, n % 2)))
    neighbour = padded.reshape(mask.shape[0], -1, 2)[:, :, ::-1].reshape(mask.shape[0], -1)[:, :n]
    return (mask * np.where(neighbour, 3, 1)).astype(np.int8).reshape(-1)


def _code_runs(code: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Runs of equal non-zero values along each row of ``code``: ``(runs, ptr)``,
    with row ``a``'s (start, end, value) in ``runs[ptr[a]:ptr[a + 1]]``."""
    padded = np.pad(code, ((0, 0), (1, 1)))
    row, x = np.nonzero(padded[:, 1:] != padded[:, :-1])  # the value changes before x
    same = row[1:] == row[:-1]
    row, start, end = row[:-1][same], x[:-1][same], x[1:][same]
    value = padded[row, start + 1]
    keep = value > 0
    ptr = np.searchsorted(row[keep], np.arange(code.shape[0] + 1)).astype(np.int64)
    return np.stack([start[keep], end[keep], value[keep]], axis=1).astype(np.int64), ptr
