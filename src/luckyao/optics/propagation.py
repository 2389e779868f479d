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
from .pupil import PupilGrid

_U = numba.uint64  # unsigned indices: numba emits no negative-index wraparound code


@numba.njit(cache=True, fastmath=True, nogil=True)
def _sample_kernel(screens, starts, n_major, n_minor, skew, major_axis, flow, u0, w0, beta, steps, layer_scales,
                   column_runs, column_ptr, row_runs, row_ptr, out):  # pragma: no cover (jit)
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
    then the minor taps and weights, shared by all lines, are applied to two
    lines at a time. Only the mask's samples are computed: ``runs[ptr[p]:ptr[p + 1]]``
    are the (start, end, lines) runs of line pair ``p`` (lines 1: the first,
    2: the second, 3: both; :func:`_pair_runs`). Footprints stay on the screens
    (checked by the caller), so every index is non-negative: indices are
    unsigned, which spares the wraparound code.
    """
    n_steps, n_dir, n, _ = out.shape
    tap = np.empty(n, np.uint64)
    weight = np.empty(n, np.float32)
    between = np.empty((2, int(beta.max() * n) + 4), np.float32)  # taps reach beta (n - 1) + 2
    out[:] = 0.0
    for l in range(starts.shape[0]):  # layer-major: footprints of one layer share cached screen lines
        if major_axis[l] == 1:  # lines are rows, points along x
            runs, ptr, line_stride, point_stride = row_runs, row_ptr, n, 1
        else:  # lines are columns: a column's points are n apart, its neighbours share cache lines
            runs, ptr, line_stride, point_stride = column_runs, column_ptr, 1, n
        m, k, n_lines = n_minor[l], skew[l], n_major[l]
        stride = _U(point_stride)
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
                    tap[b] = j
                    weight[b] = np.float32(w - j)
                for p in range(ptr.size - 1):
                    if ptr[p + 1] == ptr[p]:
                        continue
                    j_lo = tap[runs[ptr[p], 0]]
                    j_hi = tap[runs[ptr[p + 1] - 1, 1] - 1] + _U(2)
                    for h in range(min(2, n - 2 * p)):  # along the major axis first
                        u = u_first + beta[d, l] * (2 * p + h)
                        i = np.int64(u)
                        f = np.float32(u - i)
                        near = _U(starts[l] + i * m - (k * i) // n_lines + np.int64(first))
                        far = _U(starts[l] + (i + 1) * m - (k * (i + 1)) // n_lines + np.int64(first))
                        g_near = scale * (np.float32(1.0) - f)
                        g_far = scale * f
                        line = between[h]
                        for j in range(j_lo, j_hi):
                            line[j] = g_near * screens[near + j] + g_far * screens[far + j]
                    first_line, second_line = between[0], between[1]
                    o0 = _U(2 * p * line_stride)
                    o1 = o0 + _U(line_stride)
                    for r in range(ptr[p], ptr[p + 1]):  # then the minor taps, shared by the pair
                        lines = runs[r, 2]
                        if lines == 3:
                            for b in range(_U(runs[r, 0]), _U(runs[r, 1])):
                                t, c = tap[b], weight[b]
                                s0, s1 = first_line[t], first_line[t + _U(1)]
                                q0, q1 = second_line[t], second_line[t + _U(1)]
                                grid[o0 + b * stride] += s0 + c * (s1 - s0)
                                grid[o1 + b * stride] += q0 + c * (q1 - q0)
                        else:
                            values = first_line if lines == 1 else second_line
                            o = o0 if lines == 1 else o1
                            for b in range(_U(runs[r, 0]), _U(runs[r, 1])):
                                t, c = tap[b], weight[b]
                                s0, s1 = values[t], values[t + _U(1)]
                                grid[o + b * stride] += s0 + c * (s1 - s0)


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

    def __init__(self, layers: list[Layer], screens: ScreenSet, lines_of_sight: list[LineOfSight],
                 grid: PupilGrid, centre_xy_m=(0.0, 0.0), mask: np.ndarray | None = None):
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
            if (ui.min() < 0 or ui.max() + 1 >= spec.n_major
                    or (np.floor(w_lo) - offsets.max(axis=0)).min() < 0
                    or (np.floor(w_hi) + 1 - offsets.min(axis=0)).max() >= spec.n_minor):
                raise ValueError(f"footprint at height {layer.height_m} m leaves its screen: "
                                 "raise turbulence.field_radius_arcsec or shorten the case")
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
        _sample_kernel(self._screens, self._starts, self._n_major, self._n_minor, self._skew, self._major_axis,
                       self._step, self._u0, self._w0, self._beta, steps, scales,
                       *self._column_pairs, *self._row_pairs, out)
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
