"""Laser guide stars: asterism, cone effect, spot elongation and uplink geometry.

All lengths in metres, angles in radians (``*_arcsec`` only in config fields).
Pupil coordinates are centred on the telescope axis; a beacon direction is a
small-angle vector ``(theta_x, theta_y)`` [rad].

References
----------
* Cone effect (focal anisoplanatism): Tallon & Foy 1990, A&A 235, 549 -- a beacon
  at range ``H`` seen from the pupil point ``x`` crosses a layer at height ``h``
  at ``x (1 - h/H) + theta h``.
* Spot elongation: e.g. Tokovinin & Viard 2001; Neichel et al. 2013 -- a
  backscattering point at altitude ``z`` on the laser beam, seen from a
  sub-aperture at baseline ``b`` from the launch, is offset by
  ``b (1/H - 1/z)`` from the nominal spot; the total extent is
  ``~ b dH / H^2`` along the launch-to-sub-aperture direction.
"""

from dataclasses import dataclass

import numpy as np

from ..geometry import asterism_directions_rad

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))


@dataclass(frozen=True)
class LgsConfig:
    """One LGS asterism (all beacons share height, wavelength and launch).

    ``profile`` is ``"range_gate"`` (uniform backscatter over a gate of depth
    ``profile_width_m`` centred on ``height_m``, Rayleigh beacons) or
    ``"gaussian"`` (sodium layer of FWHM ``profile_width_m`` centred on
    ``height_m``). The launch telescope (diameter ``launch_diameter_m``) is at
    ``(launch_x_m, launch_y_m)`` in the pupil; on axis by default.
    """

    height_m: float = 22e3
    wavelength_m: float = 532e-9
    n_beacons: int = 4
    asterism_diameter_arcsec: float = 40.0
    asterism_rotation_deg: float = 0.0
    profile: str = "range_gate"
    profile_width_m: float = 1500.0
    launch_x_m: float = 0.0
    launch_y_m: float = 0.0
    launch_diameter_m: float = 0.35

    def __post_init__(self):
        if self.profile not in ("range_gate", "gaussian"):
            raise ValueError(f"unknown LGS profile {self.profile!r}")

    @classmethod
    def rayleigh(cls, **overrides) -> "LgsConfig":
        """Study default: 4 Rayleigh beacons at 22 km, 532 nm, 1500 m range gate."""
        return cls(**overrides)

    @classmethod
    def sodium(cls, **overrides) -> "LgsConfig":
        """Sodium alternative: 90 km, 589 nm, Gaussian layer of 10 km FWHM (assumed)."""
        values = dict(height_m=90e3, wavelength_m=589e-9, profile="gaussian", profile_width_m=10e3)
        values.update(overrides)
        return cls(**values)

    @property
    def directions_rad(self) -> np.ndarray:
        """Beacon directions (n_beacons, 2) [rad], ``(theta_x, theta_y)``."""
        return asterism_directions_rad(self.n_beacons, self.asterism_diameter_arcsec, self.asterism_rotation_deg)

    @property
    def launch_xy_m(self) -> np.ndarray:
        return np.array([self.launch_x_m, self.launch_y_m])


def altitude_limits_m(config: LgsConfig) -> tuple[float, float]:
    """Lowest and highest backscatter altitude [m] modelled for the beacon profile."""
    half_span = 0.5 * config.profile_width_m
    if config.profile == "gaussian":
        half_span = 1.5 * config.profile_width_m
    return config.height_m - half_span, config.height_m + half_span


def altitude_profile(config: LgsConfig, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Backscatter altitudes ``z`` (n,) [m] and weights (n,) summing to 1.

    ``range_gate``: midpoints of ``n`` equal slices of
    ``[H - dH/2, H + dH/2]``, equal weights (uniform backscatter over the gate;
    the ~10% density and 1/z^2 gradients over 1.5 km are neglected).
    ``gaussian``: midpoints over ``H +/- 1.5 FWHM``, Gaussian weights.
    """
    h = config.height_m
    w = config.profile_width_m
    z_low, z_high = altitude_limits_m(config)
    edges = np.linspace(z_low, z_high, n_samples + 1)
    z_m = 0.5 * (edges[1:] + edges[:-1])
    if config.profile == "range_gate":
        weights = np.ones(n_samples)
    else:
        sigma = w / FWHM_PER_SIGMA
        weights = np.exp(-0.5 * ((z_m - h) / sigma) ** 2)
    return z_m, weights / weights.sum()


def elongation_offsets_rad(subaperture_xy_m, launch_xy_m, beacon_height_m: float, altitudes_m) -> np.ndarray:
    """Angular offsets (n_sub, n_z, 2) [rad] of backscatter at ``altitudes_m``.

    Seen from a sub-aperture at ``p`` (n_sub, 2) [m], the beam point at altitude
    ``z`` appears at ``(p - l) (1/H - 1/z)`` from the nominal spot (altitude H),
    i.e. along the launch-to-sub-aperture direction, higher altitudes further
    out (exact small-angle geometry; extent ``~ b dH / H^2``).
    """
    baseline = np.asarray(subaperture_xy_m, dtype=float) - np.asarray(launch_xy_m, dtype=float)
    factor = 1.0 / beacon_height_m - 1.0 / np.asarray(altitudes_m, dtype=float)
    return baseline[:, None, :] * factor[None, :, None]
