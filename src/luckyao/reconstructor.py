"""The tomographic reconstructor product: from a case's LGS, WFS and prior config
to one MAP reconstructor per target, cached as a file keyed by that config.

``R[t]`` (n_points, n_slopes) maps one exposure's tilt-removed LGS slopes [rad]
to the tilt-removed optical path [m] along target ``t``'s line of sight at
``n_points`` pupil points (``tomography.target_reconstructor``).
"""

import logging
import time

import numpy as np
import xarray as xr

from .lgs import LgsConfig
from .pupil import Telescope
from .tomography import (SlopeGeometry, TurbulencePrior, factorize, pupil_points, slope_covariance,
                         target_reconstructor)
from .units import ARCSEC_RAD
from .wfs import ShackHartmann

log = logging.getLogger(__name__)


def lgs_config(lgs: dict) -> LgsConfig:
    """The :class:`LgsConfig` of a case's ``lgs`` block."""
    return LgsConfig(**{k: v for k, v in lgs.items() if k != "enabled"})


def shack_hartmann(telescope: Telescope, lgs: LgsConfig, wfs: dict) -> ShackHartmann:
    """The WFS of a case's ``wfs`` block, at the beacons' wavelength."""
    return ShackHartmann(telescope, wfs["n_subapertures"], lgs.wavelength_m, wfs["n_pixels"],
                         wfs["pixel_scale_arcsec"], wfs["min_illumination"], lgs.launch_diameter_m)


def build_reconstructors(spec: dict) -> xr.Dataset:
    """Reconstructors for every target of a ``config.reconstructor_spec``."""
    telescope = Telescope(spec["telescope"]["diameter_m"], spec["telescope"]["obscuration_m"])
    lgs = lgs_config(spec["lgs"])
    wfs = shack_hartmann(telescope, lgs, spec["wfs"])
    tomo = spec["tomography"]
    prior = TurbulencePrior(tomo["prior_r0_500nm_m"], tomo["prior_outer_scale_m"],
                            tuple(tomo["layer_heights_m"]), tuple(tomo["layer_cn2_fraction"]))
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    noise_rad = tomo["noise_rms_arcsec"] * ARCSEC_RAD
    _, _, points = pupil_points(telescope, wfs.subaperture_m / tomo["points_per_subaperture"])
    start = time.perf_counter()
    cholesky = factorize(slope_covariance(prior, geometry, noise_rad))
    log.info("%d slopes: covariance factorised in %.1f s", geometry.n_slopes, time.perf_counter() - start)
    matrices = []
    for x_arcsec, y_arcsec in spec["targets_arcsec"]:
        direction = (x_arcsec * ARCSEC_RAD, y_arcsec * ARCSEC_RAD)
        matrices.append(target_reconstructor(prior, geometry, noise_rad, points, direction,
                                             cholesky_lower=cholesky))
    log.info("%d targets x %d points: built in %.1f s", len(matrices), len(points), time.perf_counter() - start)
    return xr.Dataset(
        {
            "reconstructor": (("target", "point", "slope"), np.stack(matrices).astype(np.float32),
                              {"units": "m rad-1", "long_name": "tilt-removed slopes to tilt-removed optical "
                               "path along the target"}),
            "point_x_m": ("point", points[:, 0], {"units": "m", "long_name": "reconstruction point x"}),
            "point_y_m": ("point", points[:, 1], {"units": "m", "long_name": "reconstruction point y"}),
        },
        attrs={"n_slopes": geometry.n_slopes, "build_seconds": time.perf_counter() - start},
    )
