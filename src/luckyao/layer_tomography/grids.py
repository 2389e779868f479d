"""The layer grids of the layer-space tomography: one square grid per reconstructed layer.

Layer ``l`` at height ``h_l`` has ``n x n`` samples of pitch ``Delta_l = Delta (1 - h_l/H)``
(``Delta`` the pupil sampling, the sub-aperture pitch over ``o``; ``H`` the beacons' height,
:func:`luckyao.geometry.footprint_scale`), centred on the axis. With that cone-scaled pitch a
beacon's ray from pupil sample ``a`` [samples] lands at layer sample ``a + theta h_l / Delta_l + c``
(``c`` the grid's centre): a constant shift, so the ray tracing of each (beacon, layer) pair is one
bilinear stencil with constant weights (:mod:`.operators`) and is diagonal in Fourier space
(:mod:`.preconditioner`). Lines of sight to other sources (the science targets) scale the pupil
by ``1 / (1 - h_l/H)`` in layer samples and are traced by sparse bilinear matrices (:mod:`.projection`).
Arrays ``(n_layers, n, n)`` indexed ``[layer, y, x]``; lengths in metres, angles in radians.
"""

from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..geometry import footprint_scale

MARGIN_SAMPLES = 2
"""Samples kept beyond every footprint (the bilinear stencil reads one more)."""


@dataclass(frozen=True, eq=False)
class LayerGrids:
    """``n x n`` samples per layer at ``heights_m``, pitch ``pupil_pitch_m (1 - h/H)``
    for beacons at ``beacon_height_m`` (``inf``: natural stars)."""

    heights_m: tuple[float, ...]
    beacon_height_m: float
    pupil_pitch_m: float
    n: int

    @property
    def n_layers(self) -> int:
        return len(self.heights_m)

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.n_layers, self.n, self.n)

    @property
    def size(self) -> int:
        return self.n_layers * self.n * self.n

    @property
    def centre(self) -> float:
        """Index of the axis on every grid, ``(n - 1) / 2``."""
        return (self.n - 1) / 2

    @property
    def scales(self) -> np.ndarray:
        """Cone compression ``1 - h/H`` of each layer (n_layers,)."""
        return np.atleast_1d(footprint_scale(np.asarray(self.heights_m, dtype=float), self.beacon_height_m))

    @property
    def pitches_m(self) -> np.ndarray:
        """Each layer's sample pitch [m] (n_layers,)."""
        return self.pupil_pitch_m * self.scales

    def sample_index(self, layer: int, x_m, y_m) -> tuple[np.ndarray, np.ndarray]:
        """Fractional ``(column, row)`` of layer positions ``(x_m, y_m)`` [m] on ``layer``'s grid."""
        pitch = self.pitches_m[layer]
        return np.asarray(x_m) / pitch + self.centre, np.asarray(y_m) / pitch + self.centre

    @classmethod
    def covering(
        cls,
        heights_m,
        beacon_height_m: float,
        pupil_pitch_m: float,
        pupil_half_width_m: float,
        beacon_directions_rad,
        target_directions_rad=((0.0, 0.0),),
    ) -> "LayerGrids":
        """The smallest grids (``n`` a fast FFT length) holding, with :data:`MARGIN_SAMPLES`, every
        beacon's footprint of the square ``|x|, |y| <= pupil_half_width_m`` and every target's
        (a star's: not cone-compressed) on every layer."""
        heights = np.asarray(heights_m, dtype=float)
        scales = np.atleast_1d(footprint_scale(heights, beacon_height_m))
        if np.any(scales <= 0):
            raise ValueError(f"layer heights {list(heights_m)} must lie below the beacons at {beacon_height_m} m")
        beacons = np.abs(np.atleast_2d(beacon_directions_rad)).max()
        targets = np.abs(np.atleast_2d(target_directions_rad)).max()
        pitches = pupil_pitch_m * scales
        beacon_half = (pupil_half_width_m * scales + beacons * heights) / pitches
        target_half = (pupil_half_width_m + targets * heights) / pitches
        half = float(np.max(np.maximum(beacon_half, target_half)))
        n = scipy.fft.next_fast_len(2 * int(np.ceil(half)) + 2 * MARGIN_SAMPLES + 2, real=True)
        return cls(tuple(float(h) for h in heights), float(beacon_height_m), float(pupil_pitch_m), n)
