"""The LGS measurement chain of the time loop: turbulence -> slopes -> ``lgs_rms``.

For each of an exposure's ``exposure_steps`` time steps the downlink phase of
every beacon (cone effect) is sampled on the WFS pupil grid and the uplink
phase on the launch aperture (the upward beam's cone, anchored on the launch
position). The exposure gives tilt-removed slopes, and each target's
reconstructor gives the tilt-removed rms of the reconstructed wavefront along it.

A 10 ms lucky frame spans ``steps_per_frame / exposure_steps`` WFS exposures
(2 of 5 ms by default); its ``lgs_rms`` is ``sqrt(mean(rms^2))`` over them
(``tomography.lucky_frame_rms_nm``).
"""

import numpy as np

from .atmosphere import Layer
from .propagation import LineOfSight, Propagator, ScreenSet
from .pupil import Telescope
from .reconstructor import lgs_config, shack_hartmann
from .tomography import lgs_rms_nm
from .units import REFERENCE_WAVELENGTH_M
from .wfs import lgs_elongation_otf, measure_slopes


def uplink_line_of_sight(direction_rad, launch_xy_m, height_m: float) -> LineOfSight:
    """The line of sight whose cone through points ``p`` of the launch aperture is
    the uplink beam's: anchored on the launch point ``o``, the beam crosses height
    ``h`` at ``o + (p - o) s + theta h = s p + (theta + o / H) h`` (s = 1 - h/H)."""
    return LineOfSight(direction_rad[0] + launch_xy_m[0] / height_m,
                       direction_rad[1] + launch_xy_m[1] / height_m, height_m)


class LgsSensing:
    """Beacons, WFS and per-target reconstructors of one case."""

    def __init__(self, case: dict, layers: list[Layer], screens: ScreenSet, reconstructors: np.ndarray,
                 seed: int):
        telescope = Telescope(case["telescope"]["diameter_m"], case["telescope"]["obscuration_m"])
        self.lgs = lgs_config(case["lgs"])
        self.wfs = shack_hartmann(telescope, self.lgs, case["wfs"])
        self.exposure_steps = case["wfs"]["exposure_steps"]
        self.photons = case["wfs"]["photons_per_subaperture"]
        self.read_noise_e = case["wfs"]["read_noise_e"]
        self.rng = np.random.default_rng([seed, 1])
        self.reconstructors = np.asarray(reconstructors, dtype=np.float32)
        if self.reconstructors.shape[-1] != 2 * self.lgs.n_beacons * self.wfs.n_valid:
            raise ValueError("the reconstructor does not match this WFS: rebuild it")
        height = self.lgs.height_m
        directions = self.lgs.directions_rad
        launch = self.lgs.launch_xy_m
        self._down = Propagator(layers, screens, [LineOfSight(tx, ty, height) for tx, ty in directions],
                                self.wfs.grid, mask=self.wfs.sensed_mask)
        up_los = [uplink_line_of_sight(direction, launch, height) for direction in directions]
        self._up = Propagator(layers, screens, up_los, self.wfs.launch_grid, centre_xy_m=tuple(launch))
        self.elongation = lgs_elongation_otf(self.wfs, self.lgs)
        n_b, n, n_launch = len(directions), self.wfs.grid.n_pix, self.wfs.launch_grid.n_pix
        self._down_buffer = np.zeros((self.exposure_steps, n_b, n, n), dtype=np.float32)
        self._up_buffer = np.zeros((self.exposure_steps, n_b, n_launch, n_launch), dtype=np.float32)
        self.n_steps_max = min(self._down.n_steps_max, self._up.n_steps_max)

    def sample(self, steps, layer_scales) -> None:
        """Sample the beacons' down- and uplink phases of one exposure: its
        ``exposure_steps`` time ``steps`` and their ``layer_scales`` (k, n_layers)."""
        if len(steps) != self.exposure_steps:
            raise ValueError(f"an exposure has {self.exposure_steps} steps, got {len(steps)}")
        self._down.sample(steps, layer_scales, out=self._down_buffer)
        self._up.sample(steps, layer_scales, out=self._up_buffer)

    def slopes(self) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of the sampled exposure."""
        return measure_slopes(self.wfs, self._down_buffer, REFERENCE_WAVELENGTH_M, self.elongation,
                              self._up_buffer, self.photons, self.read_noise_e,
                              self.rng if self.photons is not None else None)

    def rms_nm(self, slopes: np.ndarray) -> np.ndarray:
        """Each target's reconstructed tilt-removed rms [nm] (n_targets, ...) from
        slopes (..., n_beacons, 2, n_valid): a frame's exposures in one call read
        the reconstructors once."""
        return np.array([lgs_rms_nm(r, slopes) for r in self.reconstructors])

    def exposure_slopes(self, steps, layer_scales) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of the exposure of
        time ``steps`` (see :meth:`sample`)."""
        self.sample(steps, layer_scales)
        return self.slopes()
