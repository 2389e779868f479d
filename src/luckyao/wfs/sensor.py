"""The LGS sensor of the time loop: turbulence -> tilt-removed slopes, one WFS exposure at a time.

For each of an exposure's ``exposure_steps`` time steps the downlink phase of
every beacon (cone effect) is sampled on the WFS pupil grid and the uplink
phase on the launch aperture (the upward beam's cone, anchored on the launch
position, :func:`luckyao.geometry.uplink_line_of_sight`). The exposure's
physical-optics images give tilt-removed slopes (:func:`measure_slopes`).
The sensor is open loop: it never sees the deformable mirror, so it can run
ahead of the science steps it corrects.
"""

import numpy as np

from ..atmosphere.screens import ScreenSet
from ..atmosphere.statistics import Layer
from ..geometry import LineOfSight, uplink_line_of_sight
from ..optics.propagation import Propagator
from ..seeds import wfs_noise_rng
from ..units import REFERENCE_WAVELENGTH_M
from .beacons import LgsConfig
from .centroiders import CentreOfGravity, SlopeEstimator
from .detector import add_noise
from .shack_hartmann import ShackHartmann, exposure_images, lgs_elongation_otf


def measure_slopes(
    wfs: ShackHartmann,
    downlink_phase_rad: np.ndarray,
    phase_wavelength_m: float,
    elongation: np.ndarray | None = None,
    uplink_phase_rad: np.ndarray | None = None,
    photons_per_subaperture: float | None = None,
    read_noise_e: float = 0.0,
    rng: np.random.Generator | None = None,
    estimator: SlopeEstimator | None = None,
) -> np.ndarray:
    """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of one exposure.

    Chains the optics (:func:`.shack_hartmann.exposure_images`), the detector noise
    (:func:`.detector.add_noise`, off unless ``photons_per_subaperture`` is given) and
    the ``estimator`` (default: centre of gravity, uncalibrated).
    """
    images = exposure_images(wfs, downlink_phase_rad, phase_wavelength_m, elongation, uplink_phase_rad)
    if photons_per_subaperture is not None:
        if rng is None:
            raise ValueError("noise needs an explicit rng")
        images = add_noise(images, photons_per_subaperture, read_noise_e, rng)
    if estimator is None:
        estimator = SlopeEstimator(CentreOfGravity(wfs))
    return estimator.slopes(images)


class LgsSensor:
    """Every beacon's Shack-Hartmann of one case, sampling the shared screens.

    ``photons_per_subaperture`` None: noiseless; otherwise photon and read noise
    drawn from :func:`luckyao.seeds.wfs_noise_rng` of ``seed``. ``estimator``: images -> slopes
    (default: centre of gravity, uncalibrated).
    """

    def __init__(
        self,
        lgs: LgsConfig,
        wfs: ShackHartmann,
        exposure_steps: int,
        layers: list[Layer],
        screens: ScreenSet,
        seed: int,
        photons_per_subaperture: float | None = None,
        read_noise_e: float = 0.0,
        estimator: SlopeEstimator | None = None,
    ):
        self.lgs, self.wfs, self.exposure_steps = lgs, wfs, exposure_steps
        self.estimator = SlopeEstimator(CentreOfGravity(wfs)) if estimator is None else estimator
        self.photons = photons_per_subaperture
        self.read_noise_e = read_noise_e
        self.rng = wfs_noise_rng(seed)
        height = lgs.height_m
        directions = lgs.directions_rad
        launch = lgs.launch_xy_m
        self._down = Propagator(
            layers, screens, [LineOfSight(tx, ty, height) for tx, ty in directions], wfs.grid, mask=wfs.sensed_mask
        )
        up_los = [uplink_line_of_sight(direction, launch, height) for direction in directions]
        self._up = Propagator(layers, screens, up_los, wfs.launch_grid, centre_xy_m=tuple(launch))
        self.elongation = lgs_elongation_otf(wfs, lgs)
        n_b, n, n_launch = len(directions), wfs.grid.n_pix, wfs.launch_grid.n_pix
        self._down_buffer = np.zeros((exposure_steps, n_b, n, n), dtype=np.float32)
        self._up_buffer = np.zeros((exposure_steps, n_b, n_launch, n_launch), dtype=np.float32)
        self.n_steps_max = min(self._down.n_steps_max, self._up.n_steps_max)
        self.n_slopes = 2 * lgs.n_beacons * wfs.n_valid

    def sample(self, steps, layer_scales) -> None:
        """Sample the beacons' down- and uplink phases of one exposure: its
        ``exposure_steps`` time ``steps`` and their ``layer_scales`` (k, n_layers)."""
        if len(steps) != self.exposure_steps:
            raise ValueError(f"an exposure has {self.exposure_steps} steps, got {len(steps)}")
        self._down.sample(steps, layer_scales, out=self._down_buffer)
        self._up.sample(steps, layer_scales, out=self._up_buffer)

    @property
    def downlink_phases(self) -> np.ndarray:
        """The sampled exposure's downlink phases (exposure_steps, n_beacons, n, n) float32 [rad
        at 500 nm] on the WFS grid (meaningful on ``wfs.sensed_mask``)."""
        return self._down_buffer

    def slopes(self) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of the sampled exposure."""
        return measure_slopes(
            self.wfs,
            self._down_buffer,
            REFERENCE_WAVELENGTH_M,
            self.elongation,
            self._up_buffer,
            self.photons,
            self.read_noise_e,
            self.rng if self.photons is not None else None,
            self.estimator,
        )

    def exposure_slopes(self, steps, layer_scales) -> np.ndarray:
        """Tilt-removed slopes (n_beacons, 2, n_valid) [rad] of the exposure of
        time ``steps`` (see :meth:`sample`)."""
        self.sample(steps, layer_scales)
        return self.slopes()
