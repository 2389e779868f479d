"""Geometric propagation through frozen-flow layers along lines of sight.

A ray from pupil point ``g`` [m] towards direction ``theta`` [rad] from a
source at height ``H`` crosses the layer at height ``h`` at
``(1 - h/H) g + theta h`` (cone effect; ``H = inf`` for a star). The phase
there is the layer's strip screen, moved by frozen flow, sampled by bilinear
interpolation. Because each strip moves by a whole number of its samples per
time step (see ``atmosphere``), the interpolation taps and weights are
computed once; a step only offsets them.
"""

from dataclasses import dataclass

import numba
import numpy as np

from .atmosphere import Layer, StripSpec


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


@numba.njit(cache=True, fastmath=True, nogil=True)
def _sample_kernel(screens, starts, strides, shifts, order, base, frac, layer_scale, out):
    """out[d, p] = sum_l scale[l] * bilinear(screen_l at point p, shifted by shift[l]).

    Entry ``q`` of ``base[d, l]`` and ``frac[d, l]`` (fractional along, across
    offsets) belongs to point ``order[d, l, q]``; entries ascend in screen index
    so the screen is read front to back.
    """
    n_dir, n_layer, n_pix = base.shape
    for d in range(n_dir):
        for p in range(n_pix):
            out[d, p] = 0.0
        for l in range(n_layer):
            origin = starts[l] - shifts[l]
            stride = strides[l]
            s = layer_scale[l]
            for q in range(n_pix):
                p = order[d, l, q]
                i = origin + base[d, l, q]
                fa = frac[d, l, q, 0]
                fc = frac[d, l, q, 1]
                low = screens[i] + fc * (screens[i + 1] - screens[i])
                high = screens[i + stride] + fc * (screens[i + stride + 1] - screens[i + stride])
                out[d, p] += s * (low + fa * (high - low))


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
    """Samples the summed layer phases on pupil points for several lines of sight.

    ``screens`` holds the layers' strips; ``points_x_m``/``points_y_m`` are the
    pupil points (n_pix,) [m].
    """

    def __init__(self, layers: list[Layer], screens: ScreenSet,
                 lines_of_sight: list[LineOfSight], points_x_m, points_y_m):
        specs = screens.specs
        if len(specs) != len(layers):
            raise ValueError(f"{len(layers)} layers but {len(specs)} screens")
        self._screens = screens.flat
        self._starts = screens.starts
        self._strides = np.array([s.n_across for s in specs], dtype=np.int64)
        self._k = np.array([s.samples_per_step for s in specs], dtype=np.int64)
        n_pix = len(points_x_m)
        shape = (len(lines_of_sight), len(layers), n_pix)
        self._base = np.empty(shape, dtype=np.int32)
        self._frac = np.empty(shape + (2,), dtype=np.float32)
        for d, los in enumerate(lines_of_sight):
            for l, (layer, spec) in enumerate(zip(layers, specs)):
                x, y = footprint_m(points_x_m, points_y_m, layer.height_m, los)
                self._base[d, l], self._frac[d, l] = _bilinear_taps(x, y, layer, spec)
        # store each (direction, layer)'s points in ascending screen index
        self._order = np.argsort(self._base, axis=-1, kind="stable").astype(np.int32)
        self._base = np.take_along_axis(self._base, self._order, axis=-1)
        self._frac = np.take_along_axis(self._frac, self._order[..., None], axis=-2)
        first_row = (self._base // self._strides[None, :, None]).min(axis=(0, 2))
        moving = self._k > 0
        self.n_steps_max = int(np.min(first_row[moving] // self._k[moving] + 1)) if moving.any() else 2**62
        """Steps for which every footprint stays on its screen."""

    def sample(self, step: int, layer_scale) -> np.ndarray:
        """Phases (n_los, n_pix) float32 at time step ``step``; layer ``l`` weighted by
        ``layer_scale[l]`` (e.g. r0^-5/6 sqrt(Cn2 fraction) for rad at 500 nm)."""
        if not 0 <= step < self.n_steps_max:
            raise IndexError(f"step {step} outside the screens' {self.n_steps_max} steps")
        out = np.empty(self._base.shape[::2], dtype=np.float32)
        _sample_kernel(self._screens, self._starts, self._strides, step * self._k * self._strides,
                       self._order, self._base, self._frac, np.asarray(layer_scale, dtype=np.float32), out)
        return out


def _bilinear_taps(x_m, y_m, layer: Layer, spec: StripSpec):
    """Flat index (within the layer) of each point's first tap at t = 0 and its
    fractional (along, across) offsets, for points (x, y) [m] in the sky frame."""
    e = layer.wind_unit
    along = (x_m * e[0] + y_m * e[1] - spec.origin_m[0]) / spec.dx_m
    across = (-x_m * e[1] + y_m * e[0] - spec.origin_m[1]) / spec.dx_m
    i = np.floor(along).astype(np.int64)
    j = np.floor(across).astype(np.int64)
    if i.min() < 0 or i.max() + 1 >= spec.n_along or j.min() < 0 or j.max() + 1 >= spec.n_across:
        raise ValueError(
            f"footprint at height {layer.height_m} m leaves its screen: "
            "raise turbulence.field_radius_arcsec or shorten the case")
    if spec.n_along * spec.n_across >= 2**31:
        raise ValueError(f"screen of layer at {layer.height_m} m has over 2^31 samples")
    frac = np.stack([along - i, across - j], axis=-1).astype(np.float32)
    return (i * spec.n_across + j).astype(np.int32), frac
