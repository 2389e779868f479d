"""Tilt anisoplanatism: the variance of the difference between the image motions (G-tilt, the
pupil-averaged phase gradient, which an image's centre of gravity measures) of two directions
``theta`` apart, in a layered von Karman atmosphere (Sasiela 1994, *Electromagnetic Wave
Propagation in Turbulence*, ch. 7; Hardy 1998, *Adaptive Optics for Astronomical Telescopes*,
sec. 9.3.2):

``sigma^2_a(theta) = 2 sum_l c_l lambda^2 int d^2f f_a^2 Phi(f) |A(f)|^2 (1 - cos(2 pi f . h_l theta))``

per image axis ``a``, with ``Phi`` the von Karman phase spectrum at ``lambda`` (500 nm: the
image motion in radians does not depend on the wavelength), ``c_l`` and ``h_l`` the layers'
Cn^2 fractions and heights, and ``A`` the pupil's mean (the annulus' normalised transform). Over
the angle of ``f`` the integral is ``pi (1 - J0(z) + J2(z) cos 2 beta)``, ``z = 2 pi f h_l theta``,
``beta`` the angle between the axis and the separation: at small separations the motion along
the separation differs three times as much as across it; at large ones the two directions'
motions are independent and the variance is twice one direction's (G-tilt, one axis, Kolmogorov:
``0.170 (lambda/D)^2 (D/r0)^(5/3)``, Tyler 1994, JOSA A 11, 358).

A DM conjugate to the pupil moves every direction's image alike: the differential tilt of an
AO case is that of the atmosphere.
"""

import numpy as np
from scipy.special import j0, j1, jv

from ..units import REFERENCE_WAVELENGTH_M
from .statistics import von_karman_psd

_FREQUENCIES_PER_DIAMETER = np.geomspace(1e-15, 400.0, 80001)
"""The integral's spatial frequencies [cycles per telescope diameter], log-spaced. One direction's
Kolmogorov G-tilt converges slowly at low frequencies (the integrand ~f^(1/3) d ln f): below 1e-15
lies 1e-5 of it; above 400 the pupil's transform (~f^-3/2) leaves < 1e-5."""


def pupil_mean_transform(f_per_m, diameter_m: float, obscuration_m: float = 0.0):
    """The Fourier transform of an annular pupil divided by its area (1 at f = 0)."""

    def disc(d):
        x = np.pi * d * np.asarray(f_per_m, dtype=float)
        return d**2 * np.where(x > 0, 2 * j1(x) / np.where(x > 0, x, 1.0), 1.0)

    return (disc(diameter_m) - (disc(obscuration_m) if obscuration_m > 0 else 0.0)) / (diameter_m**2 - obscuration_m**2)


def differential_tilt_variance_rad2(
    separation_arcsec,
    heights_m,
    cn2_fraction,
    r0_500nm_m: float,
    outer_scale_m: float,
    diameter_m: float,
    obscuration_m: float = 0.0,
) -> np.ndarray:
    """Variance [rad^2] of the difference of two directions' image motions (module docstring),
    per image axis (x, y): ``separation_arcsec`` (..., 2) the (x, y) separation; returns (..., 2)."""
    separation = np.asarray(separation_arcsec, dtype=float)
    theta = np.hypot(separation[..., 0], separation[..., 1]) * np.pi / (180 * 3600)  # (...,) rad
    beta = np.arctan2(separation[..., 1], separation[..., 0])  # from the x axis
    f = _FREQUENCIES_PER_DIAMETER / diameter_m
    weight = (
        np.pi
        * REFERENCE_WAVELENGTH_M**2
        * f**3
        * von_karman_psd(f, r0_500nm_m, outer_scale_m)
        * pupil_mean_transform(f, diameter_m, obscuration_m) ** 2
        * f  # d f = f d ln f
    )
    d_log_f = np.log(_FREQUENCIES_PER_DIAMETER[1] / _FREQUENCIES_PER_DIAMETER[0])
    isotropic, anisotropic = np.zeros(theta.shape), np.zeros(theta.shape)
    for height, fraction in zip(heights_m, cn2_fraction):
        z = 2 * np.pi * f * (height * theta)[..., None]
        isotropic += 2 * fraction * np.trapezoid(weight * (1 - j0(z)), dx=d_log_f, axis=-1)
        anisotropic += 2 * fraction * np.trapezoid(weight * jv(2, z), dx=d_log_f, axis=-1)
    cos2 = np.cos(2 * beta)
    return np.stack([isotropic + anisotropic * cos2, isotropic - anisotropic * cos2], axis=-1)
