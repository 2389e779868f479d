"""The calibrated slope response of the physical-optics LGS Shack-Hartmann.

The tomography and the DM slopes assume slopes = mean gradient of the optical
path over each sub-aperture [rad]. The physical-optics sensor (0.84" pixels,
elongated spots broadened by the seeing) responds to it with a gain well below 1,
measured here per sub-aperture through the sensor model, as an interaction matrix
is measured on a real system, under turbulence of the seeing the case assumes:

* draws: independent von Karman phases of the turbulence as each LGS sees it through
  its cone (:class:`BeaconSeeing`), on the downlink pupil and on the launch aperture
  (uplink spot), one WFS time step each;
* push-pull dithers: each draw is sensed with a tilt ``+-delta`` along x and along y
  added over the whole pupil; ``(s(+delta) - s(-delta)) / 2 delta`` is a column of the
  sub-aperture's 2 x 2 response (the turbulence's own slopes cancel to first order,
  so few draws suffice);
* the response is the mean over draws and beacons: the beacons' spots share their
  elongation (it depends on the sub-aperture's baseline to the launch, not on the
  beacon's direction) and their seeing, so every LGS has the same response
  per sub-aperture; pooling them is 4x the draws.

The mean local gain over Gaussian slopes equals the regression gain of the measured
on the true slopes (Bussgang 1952; Stein's lemma), so it is the gain the turbulence's
slopes see, not only that of small signals. The centroider's positions are then
mapped into the assumed units, ``s = G^-1 s_measured`` per sub-aperture
(:class:`SlopeResponse`), before each beacon's tilt is removed. Static offsets
(reference slopes) are not calibrated: the elongation's is below 0.01" and the
turbulence's own slopes (~0.2" rms) would need far more draws to resolve them.
"""

from dataclasses import dataclass

import numpy as np

from ..atmosphere.screens import periodic_screen_amplitude, periodic_screen_pair
from ..atmosphere.statistics import r0_at_wavelength, von_karman_psd, von_karman_structure_function
from ..geometry import footprint_scale
from ..units import REFERENCE_WAVELENGTH_M
from .sampling import calibration_screen_size
from .shack_hartmann import ShackHartmann, exposure_images, intensity_samples, intensity_spectra, uplink_otf

DITHER_PIXELS = 0.05
"""Push-pull dither [pixels]: small against the spot (linear), large against float32 rounding."""


@dataclass(frozen=True)
class BeaconSeeing:
    """Von Karman turbulence as an LGS at ``beacon_height_m`` sees it: layer ``l`` (Cn2
    fraction ``f_l`` at ``h_l``) is compressed by the cone, ``c_l = 1 - h_l / H``, so on
    the pupil it has ``r0_l = r0 f_l^(-3/5) / c_l`` and outer scale ``L0 / c_l``
    (``D(c r; r0, L0) = D(r; r0/c, L0/c)``; Tallon & Foy 1990). The uplink beam,
    converging from the launch aperture to the beacon, sees the same statistics."""

    r0_500nm_m: float
    outer_scale_m: float
    heights_m: tuple[float, ...]
    cn2_fraction: tuple[float, ...]
    beacon_height_m: float

    def _layers(self):
        """(r0 [m at 500 nm], L0 [m]) of each layer below the beacon, on the pupil."""
        scales = footprint_scale(self.heights_m, self.beacon_height_m)
        return [
            (self.r0_500nm_m * f ** (-3 / 5) / c, self.outer_scale_m / c)
            for f, c in zip(self.cn2_fraction, scales)
            if f > 0 and c > 0
        ]

    def psd(self, f_per_m):
        """Phase power spectrum [rad^2 m^2 at 500 nm] on the pupil: the layers' sum."""
        return sum(von_karman_psd(f_per_m, r0, l0) for r0, l0 in self._layers())

    def structure_function(self, r_m, wavelength_m: float = REFERENCE_WAVELENGTH_M):
        """Phase structure function [rad^2 at ``wavelength_m``] on the pupil."""
        return sum(
            von_karman_structure_function(r_m, r0_at_wavelength(r0, wavelength_m), l0) for r0, l0 in self._layers()
        )


def reference_spot_spectra(wfs: ShackHartmann, elongation: np.ndarray | None, seeing: BeaconSeeing) -> np.ndarray:
    """Fourier coefficients (n_valid, M, M//2+1) complex64 of each sub-aperture's
    long-exposure spot: the sub-aperture's diffraction OTF x the launch aperture's x
    the elongation x the atmospheric OTF ``exp(-D(lambda f) / 2)`` of the down- and of
    the uplink (Roddier 1981). The correlation centroider's reference."""
    grid = wfs.grid.n_pix
    diffraction = intensity_spectra(wfs, intensity_samples(wfs, np.zeros((1, grid, grid)), wfs.wavelength_m))[0]
    launch = uplink_otf(wfs, np.zeros((wfs.launch_grid.n_pix,) * 2), wfs.wavelength_m)
    f_y, f_x = wfs.harmonics
    separation_m = wfs.wavelength_m * np.hypot(f_y[:, None], f_x[None, :])
    atmosphere = np.exp(-seeing.structure_function(separation_m, wfs.wavelength_m))  # down x up
    spectra = diffraction * launch * atmosphere
    if elongation is not None:
        spectra = spectra * elongation
    return spectra.astype(np.complex64)


@dataclass(frozen=True)
class SlopeResponse:
    """Measured response of each sub-aperture, ``s_measured = G s``: ``matrix`` (2 out,
    2 in, n_valid) [1], with the standard error of its mean ``matrix_error`` (or None)."""

    matrix: np.ndarray
    matrix_error: np.ndarray | None = None

    def __post_init__(self):
        inverse = np.linalg.inv(np.moveaxis(np.asarray(self.matrix, dtype=float), -1, 0))  # (n_valid, 2, 2)
        object.__setattr__(self, "_inverse", np.ascontiguousarray(np.moveaxis(inverse, 0, -1), dtype=np.float32))

    def apply(self, positions: np.ndarray) -> np.ndarray:
        """Positions (n_beacons, 2, n_valid) [rad] in the assumed units, ``G^-1 s``."""
        return np.einsum("ijv,bjv->biv", self._inverse, np.asarray(positions, dtype=np.float32))


def measure_response(
    wfs: ShackHartmann,
    elongation: np.ndarray | None,
    seeing: BeaconSeeing,
    centroider,
    n_beacons: int,
    draws: int,
    rng: np.random.Generator,
    dither_rad: float | None = None,
) -> SlopeResponse:
    """The response of ``centroider`` on ``wfs`` by push-pull dithers on ``draws`` x
    ``n_beacons`` (<= 4) independent turbulence draws of ``seeing`` (module docstring).

    ``dither_rad`` defaults to :data:`DITHER_PIXELS` pixels. Cost: 4 exposures of
    ``n_beacons`` sensors per draw.
    """
    if not 1 <= n_beacons <= 4:
        raise ValueError("1 to 4 beacons per draw")
    dither = DITHER_PIXELS * wfs.pixel_scale_rad if dither_rad is None else dither_rad
    n, n_launch = wfs.grid.n_pix, wfs.launch_grid.n_pix
    size = calibration_screen_size(n)
    amplitude = periodic_screen_amplitude(seeing.psd, size, wfs.grid.dx_m)
    corners = [((k // 2) * size // 2, (k % 2) * size // 2) for k in range(n_beacons)]
    x, y = wfs.grid.xy_m
    ramps = 2 * np.pi * dither * np.stack([x, y]) / REFERENCE_WAVELENGTH_M  # rad at 500 nm
    columns = np.empty((draws, n_beacons, 2, 2, wfs.n_valid))
    for d in range(draws):
        down_screen, up_screen = periodic_screen_pair(amplitude, rng)
        down = np.stack([down_screen[i : i + n, j : j + n] for i, j in corners])[None]
        up = np.stack([up_screen[i : i + n_launch, j : j + n_launch] for i, j in corners])[None]
        for axis in range(2):
            plus, minus = (
                centroider.positions(
                    exposure_images(wfs, down + sign * ramps[axis], REFERENCE_WAVELENGTH_M, elongation, up)
                ).astype(float)
                for sign in (1.0, -1.0)
            )
            columns[d, :, :, axis] = (plus - minus) / (2 * dither)
    columns = columns.reshape(draws * n_beacons, 2, 2, wfs.n_valid)
    return SlopeResponse(columns.mean(axis=0), columns.std(axis=0, ddof=1) / np.sqrt(len(columns)))
