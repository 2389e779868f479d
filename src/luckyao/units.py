"""Unit conversions used at the config and plot boundaries (SI inside)."""

import numpy as np

ARCSEC_RAD = np.pi / (180.0 * 3600.0)
"""One arcsecond in radians."""

REFERENCE_WAVELENGTH_M = 500e-9
"""Wavelength at which r0 and stored phases are referenced [m]."""


def phase_rad_to_nm(phase_rad, wavelength_m):
    """Optical path difference [nm] of a phase [rad] at ``wavelength_m``."""
    return np.asarray(phase_rad) * wavelength_m / (2 * np.pi) * 1e9
