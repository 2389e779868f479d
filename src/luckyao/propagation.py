"""Geometric propagation through frozen-flow layers along lines of sight.

A ray from pupil point ``g`` [m] towards direction ``theta`` [rad] from a
source at height ``H`` crosses the layer at height ``h`` at
``(1 - h/H) g + theta h`` (cone effect; ``H = inf`` for a star). The phase
there is the layer's strip screen, moved by frozen flow (any sub-sample shift),
sampled by bilinear interpolation. The footprints of a regular pupil grid are
an affine image of it on each strip, so a compiled kernel computes every tap
and weight on the fly: nothing but the screens is read from memory.
"""

from dataclasses import dataclass

import numba
import numpy as np

from .atmosphere import Layer, StripSpec
from .pupil import PupilGrid


@dataclass(frozen=True)
class LineOfSight:
    """Direction ``(theta_x, theta_y)`` [rad] to a source at ``height_m`` (inf: a star)."""

    theta_x_rad: float
    theta_y_rad: float
    height_m: float = np.inf


def footprint_m(points_x_m, points_y_m, layer_height_m, los: LineOfSight):
    """Positions (x, y) [m] where rays from pupil points cross a layer (cone effect)."""
    scale = 1.0 - layer_height_m / los.height_m if np.isfinite(los.height_m) else 1.0
    return (scale * np.asarray(points_x_m) + los.theta_x_rad * layer_height_m,
            scale * np.asarray(points_y_m) + los.theta_y_rad * layer_height_m)


_U = numba.uint64  # unsigned indices: no negative-index wraparound, faster gathers


@numba.njit(cache=True, fastmath=True, nogil=True)
def _sample_kernel(screens, starts, strides, shifts, affine, row_start, row_end, layer_scale,
                   out):  # pragma: no cover (jit)
    """out[d, y, x] = sum_l scale[l] * bilinear(screen_l at the grid point's footprint),
    for ``row_start[y] <= x < row_end[y]`` (zero elsewhere).

    ``affine[d, l]`` = (along0, across0, d_along/dx, d_across/dx, d_along/dy,
    d_across/dy) in screen samples at t = 0; ``shifts[l]`` the frozen-flow shift
    [samples along the wind] now. Per row, a first loop computes taps and
    weights (vectorisable), a second gathers and blends. Footprints stay on the
    screens (checked by the caller), so every index is non-negative.
    """
    n_dir, n_y, n_x = out.shape
    tap = np.empty(n_x, np.uint64)
    w_along = np.empty(n_x, np.float32)
    w_across = np.empty(n_x, np.float32)
    flat = out.reshape(-1)
    flat[:] = 0.0
    for d in range(n_dir):
        for i_layer in range(starts.shape[0]):
            origin = _U(starts[i_layer])
            stride = _U(strides[i_layer])
            scale = np.float32(layer_scale[i_layer])
            a0 = affine[d, i_layer, 0] - shifts[i_layer]
            c0, a_x, c_x = affine[d, i_layer, 1], affine[d, i_layer, 2], affine[d, i_layer, 3]
            a_y, c_y = affine[d, i_layer, 4], affine[d, i_layer, 5]
            for y in range(n_y):
                row_a = a0 + y * a_y
                row_c = c0 + y * c_y
                for x in range(row_start[y], row_end[y]):
                    along = row_a + x * a_x
                    across = row_c + x * c_x
                    i = np.uint64(along)
                    j = np.uint64(across)
                    w_along[x] = np.float32(along - i)
                    w_across[x] = np.float32(across - j)
                    tap[x] = origin + i * stride + j
                base = _U((d * n_y + y) * n_x)
                for x in range(row_start[y], row_end[y]):
                    t = tap[x]
                    s00, s01 = screens[t], screens[t + _U(1)]
                    s10, s11 = screens[t + stride], screens[t + stride + _U(1)]
                    low = s00 + w_across[x] * (s01 - s00)
                    high = s10 + w_across[x] * (s11 - s10)
                    flat[base + _U(x)] += scale * (low + w_along[x] * (high - low))


@dataclass(frozen=True, eq=False)
class ScreenSet:
    """Every layer's strip, flattened into one float32 buffer (possibly memory-mapped).

    Layer ``l`` occupies ``flat[starts[l] : starts[l] + n_along * n_across]`` in
    row-major (along, across) order.
    """

    specs: tuple[StripSpec, ...]
    flat: np.ndarray
    starts: np.ndarray

    @classmethod
    def from_screens(cls, specs, screens) -> "ScreenSet":
        sizes = [s.n_along * s.n_across for s in specs]
        flat = np.concatenate([np.asarray(s, dtype=np.float32).ravel() for s in screens])
        return cls(tuple(specs), flat, np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64))

    def screen(self, layer: int) -> np.ndarray:
        s = self.specs[layer]
        start = self.starts[layer]
        return self.flat[start:start + s.n_along * s.n_across].reshape(s.n_along, s.n_across)


class Propagator:
    """Samples the summed layer phases on a pupil grid for several lines of sight.

    ``grid`` (centred on ``centre_xy_m`` [m] in the pupil) is sampled for each
    line of sight, where ``mask`` (n, n) is true (default: everywhere; the
    samples of a row between its first and last true one are computed, others
    are zero); ``screens`` holds the layers' strips.
    """

    def __init__(self, layers: list[Layer], screens: ScreenSet, lines_of_sight: list[LineOfSight],
                 grid: PupilGrid, centre_xy_m=(0.0, 0.0), mask: np.ndarray | None = None):
        specs = screens.specs
        if len(specs) != len(layers):
            raise ValueError(f"{len(layers)} layers but {len(specs)} screens")
        self.grid = grid
        mask = np.ones((grid.n_pix, grid.n_pix), bool) if mask is None else np.asarray(mask, bool)
        has = mask.any(axis=1)
        self._row_start = np.where(has, mask.argmax(axis=1), 0).astype(np.int64)
        self._row_end = np.where(has, grid.n_pix - mask[:, ::-1].argmax(axis=1), 0).astype(np.int64)
        self._screens = screens.flat
        self._starts = screens.starts
        self._strides = np.array([s.n_across for s in specs], dtype=np.int64)
        self._shift = np.array([s.shift_per_step for s in specs])
        self._affine = np.empty((len(lines_of_sight), len(layers), 6))
        first_row = np.full(len(layers), np.inf)
        c = grid.coords_m
        corners_x = centre_xy_m[0] + np.array([c[0], c[-1], c[0], c[-1]])
        corners_y = centre_xy_m[1] + np.array([c[0], c[0], c[-1], c[-1]])
        for d, los in enumerate(lines_of_sight):
            for i_layer, (layer, spec) in enumerate(zip(layers, specs)):
                origin = _screen_position(*footprint_m(corners_x[0], corners_y[0], layer.height_m, los), layer, spec)
                step_x = _screen_position(*footprint_m(corners_x[0] + grid.dx_m, corners_y[0], layer.height_m, los),
                                          layer, spec) - origin
                step_y = _screen_position(*footprint_m(corners_x[0], corners_y[0] + grid.dx_m, layer.height_m, los),
                                          layer, spec) - origin
                self._affine[d, i_layer] = [origin[0], origin[1], step_x[0], step_x[1], step_y[0], step_y[1]]
                along, across = _screen_position(*footprint_m(corners_x, corners_y, layer.height_m, los), layer, spec)
                if (along.min() < 0 or along.max() + 1 >= spec.n_along or across.min() < 0
                        or across.max() + 1 >= spec.n_across):
                    raise ValueError(f"footprint at height {layer.height_m} m leaves its screen: "
                                     "raise turbulence.field_radius_arcsec or shorten the case")
                first_row[i_layer] = min(first_row[i_layer], along.min())
        moving = self._shift > 0
        self.n_steps_max = int(np.min(np.floor(first_row[moving] / self._shift[moving])) + 1) if moving.any() else 2**62
        """Steps for which every footprint stays on its screen."""

    def sample(self, step: int, layer_scale) -> np.ndarray:
        """Phases (n_los, n, n) float32 on the grid at time step ``step``; layer ``l``
        weighted by ``layer_scale[l]`` (e.g. r0^-5/6 sqrt(Cn2 fraction): rad at 500 nm)."""
        if not 0 <= step < self.n_steps_max:
            raise IndexError(f"step {step} outside the screens' {self.n_steps_max} steps")
        n = self.grid.n_pix
        out = np.empty((self._affine.shape[0], n, n), dtype=np.float32)
        _sample_kernel(self._screens, self._starts, self._strides, step * self._shift, self._affine,
                       self._row_start, self._row_end, np.asarray(layer_scale, dtype=np.float32), out)
        return out


def _screen_position(x_m, y_m, layer: Layer, spec: StripSpec) -> np.ndarray:
    """(along, across) position [samples] on the layer's strip at t = 0 of sky points [m]."""
    e = layer.wind_unit
    along = (np.asarray(x_m) * e[0] + np.asarray(y_m) * e[1] - spec.origin_m[0]) / spec.dx_m
    across = (-np.asarray(x_m) * e[1] + np.asarray(y_m) * e[0] - spec.origin_m[1]) / spec.dx_m
    return np.array([along, across])
