"""Von Karman statistics of a layered atmosphere, and r0 in time.

Phase in rad at the wavelength where ``r0`` is given; r0 scales as
``lambda ** (6/5)`` and phase in rad as ``1 / lambda`` (Fried 1966; Roddier 1981).
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import gamma, kv

from ..units import REFERENCE_WAVELENGTH_M

_VK_COEFFICIENT = (24 / 5 * gamma(6 / 5)) ** (5 / 6) * gamma(11 / 6) ** 2 / (2 * np.pi ** (11 / 3))
"""0.022896, the constant of the Kolmogorov phase PSD Phi(f) = 0.0229 r0^(-5/3) f^(-11/3)."""


@dataclass(frozen=True)
class Layer:
    """One frozen-flow layer; the wind direction is where the turbulence moves to,
    counted from +x towards +y."""

    height_m: float
    cn2_fraction: float
    wind_speed_m_s: float
    wind_direction_deg: float

    @property
    def wind_unit(self) -> np.ndarray:
        a = np.deg2rad(self.wind_direction_deg)
        return np.array([np.cos(a), np.sin(a)])


def von_karman_psd(f_per_m, r0_m, outer_scale_m):
    """Phase power spectral density [rad^2 m^2], Phi = 0.0229 r0^-5/3 (f^2 + 1/L0^2)^-11/6.

    Phase in rad at the wavelength where ``r0_m`` is given (Roddier 1981).
    """
    f2 = np.asarray(f_per_m, dtype=float) ** 2
    return _VK_COEFFICIENT * r0_m ** (-5 / 3) * (f2 + outer_scale_m**-2) ** (-11 / 6)


def von_karman_covariance(r_m, r0_m, outer_scale_m):
    """Phase covariance B(r) [rad^2] of von Karman turbulence (e.g. Conan 2000).

    ``B(r) = (L0/r0)^(5/3) c (2 pi r/L0)^(5/6) K_(5/6)(2 pi r/L0)`` with
    ``c = 2^(-5/6) Gamma(11/6) pi^(-8/3) (24/5 Gamma(6/5))^(5/6)``; at r = 0 the
    limit ``x^(5/6) K_(5/6)(x) -> 2^(-1/6) Gamma(5/6)`` is used.
    """
    r = np.asarray(r_m, dtype=float)
    coefficient = (
        (outer_scale_m / r0_m) ** (5 / 3)
        * 2 ** (-5 / 6)
        * gamma(11 / 6)
        / np.pi ** (8 / 3)
        * (24 / 5 * gamma(6 / 5)) ** (5 / 6)
    )
    x = 2 * np.pi * r / outer_scale_m
    at_zero = coefficient * 2 ** (-1 / 6) * gamma(5 / 6)
    with np.errstate(invalid="ignore", divide="ignore"):
        value = coefficient * x ** (5 / 6) * kv(5 / 6, x)
    return np.where(x > 0, value, at_zero)


def von_karman_structure_function(r_m, r0_m, outer_scale_m):
    """Phase structure function D(r) = 2 (B(0) - B(r)) [rad^2]; tends to
    6.88 (r/r0)^(5/3) for r << L0."""
    return 2 * (von_karman_covariance(0.0, r0_m, outer_scale_m) - von_karman_covariance(r_m, r0_m, outer_scale_m))


def r0_at_wavelength(r0_m, wavelength_m, reference_wavelength_m=REFERENCE_WAVELENGTH_M):
    """Fried parameter at ``wavelength_m`` from its value at the reference: r0 ∝ lambda^(6/5)."""
    return r0_m * (wavelength_m / reference_wavelength_m) ** (6 / 5)


@dataclass(frozen=True)
class R0Schedule:
    """r0 at 500 nm in time: constant (``amplitude_m = 0``) or sinusoidal,
    ``r0(t) = mean_m + amplitude_m sin(2 pi t / period_s)``."""

    mean_m: float
    amplitude_m: float = 0.0
    period_s: float = 1.0

    def r0_m(self, time_s):
        t = np.asarray(time_s, dtype=float)
        return self.mean_m + self.amplitude_m * np.sin(2 * np.pi * t / self.period_s)
