"""One photometric scale: a star's magnitude and the photons a lucky frame detects of it.

A star of magnitude ``m`` gives ``N = N_0 10^(-m / 2.5)`` detected photons per frame, with
``N_0`` those of magnitude 0::

    N_0 = F_0 dlambda A T t / (h c / lambda)

``F_0`` [W m^-2 um^-1] the band's zero point (Vega's flux density at its centre
``lambda``), ``dlambda`` [um] its width, ``A`` [m^2] the telescope's collecting area (its
central obscuration taken away), ``T`` the throughput (atmosphere, telescope, instrument and
the detector's quantum efficiency together), ``t`` [s] the frame time, ``h c / lambda`` the
photon energy. The band's part (``F_0``, ``lambda``, ``dlambda``, ``T``) is the study's
``photometry`` config block (:class:`Photometry`; defaults in ``studyspec/schema.yaml``); ``A``
and ``t`` are each case's (``telescope``, ``camera.frame_time_s``): 8.69e8 photons per 10 ms
frame at I = 0 on the 4.2 m telescope (1.2 m obscuration), 866 at I = 15, 55 at I = 18.

The source paper converts twice, and its two conversions disagree: 1,000 photons per frame is
I = 15 (N_0 = 1.0e9) and 100 is I = 18 (N_0 = 1.6e9), half a magnitude apart for the same
flux ratio. This scale is within 0.15 mag of the first (1,000 photons is I = 14.84) and 0.65
mag from the second (100 photons is I = 17.35). Every magnitude the study draws or writes
(the ``registration`` figure's top axis, its knees' table, the ``limiting_magnitude`` figure) is
of this scale, this module's formula.
"""

from dataclasses import dataclass

import numpy as np

PLANCK_J_S = 6.62607015e-34
"""Planck's constant [J s] (exact, SI 2019)."""
LIGHT_M_S = 2.99792458e8
"""The speed of light [m/s] (exact)."""


def config_with_defaults(config: dict | None = None) -> dict:
    """A study's ``photometry`` block with the schema's defaults of the keys it leaves out (their
    one home): what a figure's settings carry."""
    from .studyspec.schema import load_schema

    keys = load_schema()["properties"]["photometry"]["properties"]
    unknown = set(config or {}) - set(keys)
    if unknown:
        raise ValueError(f"photometry: unknown keys {sorted(unknown)}")
    return {key: (config or {}).get(key, spec["default"]) for key, spec in keys.items()}


def collecting_area_m2(diameter_m: float, obscuration_m: float) -> float:
    """A telescope's collecting area, its central obscuration's taken away [m^2]."""
    return np.pi / 4 * (diameter_m**2 - obscuration_m**2)


@dataclass(frozen=True)
class Photometry:
    """The band of the photometric scale (module docstring): its name, centre [um], zero point
    [W m^-2 um^-1], width [um] and the throughput. The defaults are the schema's
    (``photometry``, :meth:`from_config`): a long-pass I (+ z) band as lucky cameras use, Vega's
    I-band flux density (Bessell, Castelli & Plez 1998: 1.13e-9 erg s^-1 cm^-2 A^-1), half the
    photons detected."""

    band: str
    wavelength_um: float
    zero_point_w_m2_um: float
    bandwidth_um: float
    throughput: float

    @classmethod
    def from_config(cls, config: dict | None = None) -> "Photometry":
        """From a study's ``photometry`` block, the keys it leaves out (all, if None) the
        schema's defaults (:func:`config_with_defaults`)."""
        return cls(**config_with_defaults(config))

    def photons_at_zero_magnitude(self, area_m2: float, frame_time_s: float) -> float:
        """``N_0``: detected photons per frame of a magnitude-0 star through a collecting area
        ``area_m2`` [m^2] in frames of ``frame_time_s`` [s] (module docstring)."""
        photon_energy_j = PLANCK_J_S * LIGHT_M_S / (self.wavelength_um * 1e-6)
        power_w = self.zero_point_w_m2_um * self.bandwidth_um * area_m2 * self.throughput
        return power_w * frame_time_s / photon_energy_j

    def magnitude(self, photons_per_frame, area_m2: float, frame_time_s: float):
        """The magnitude of a star giving ``photons_per_frame`` detected photons per frame (:func:`magnitude_of`)."""
        return magnitude_of(photons_per_frame, self.photons_at_zero_magnitude(area_m2, frame_time_s))

    def photons_per_frame(self, magnitude, area_m2: float, frame_time_s: float):
        """The detected photons per frame of a star of ``magnitude`` (:func:`photons_of`)."""
        return photons_of(magnitude, self.photons_at_zero_magnitude(area_m2, frame_time_s))

    def describe(self) -> str:
        """The scale in words, for a figure's legend."""
        return (
            f"{self.band} band: {self.zero_point_w_m2_um:.3g} W m-2 um-1 at {self.wavelength_um:g} um, "
            f"{self.bandwidth_um * 1e3:g} nm wide, throughput {self.throughput:g}"
        )


def magnitude_of(photons_per_frame, zero_photons: float):
    """``m = 2.5 log10(N_0 / N)``: the magnitude of a star giving ``photons_per_frame`` (``N``)
    detected photons per frame on a scale whose magnitude 0 gives ``zero_photons`` (``N_0``)."""
    return 2.5 * np.log10(zero_photons / np.asarray(photons_per_frame, dtype=float))


def photons_of(magnitude, zero_photons: float):
    """``N = N_0 10^(-m / 2.5)``: the inverse of :func:`magnitude_of`."""
    return zero_photons * 10 ** (-0.4 * np.asarray(magnitude, dtype=float))


def case_aperture(config: dict) -> tuple[float, float]:
    """A case's collecting area [m^2] and frame time [s] from its resolved config (its
    ``telescope`` and ``camera.frame_time_s``): what the scale needs of it besides the band."""
    from .studyspec.case import Case

    telescope = Case.from_config(config).telescope
    return collecting_area_m2(telescope.diameter_m, telescope.obscuration_m), config["camera"]["frame_time_s"]
