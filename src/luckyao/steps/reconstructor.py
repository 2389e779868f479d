"""The cached products of the LGS tomography, each a file keyed by the config it depends on.

* Reconstructors: from a case's LGS, WFS and prior config, one MAP
  reconstructor per target: ``R[t]`` (n_points, n_slopes) maps one exposure's
  tilt-removed LGS slopes [rad] to the tilt-removed optical path [m] along target
  ``t``'s line of sight at ``n_points`` pupil points (``tomography.target_reconstructor``).
* AO commands: the open-loop command matrix (slopes -> DM commands, LTAO or GLAO,
  :func:`luckyao.ao.control.command_matrix`) and the DM's slopes as every WFS
  sees them (:func:`luckyao.ao.control.dm_slopes_matrix`).
"""

import logging
import time

import numpy as np
import xarray as xr

from ..ao.control import command_matrix, dm_slopes_matrix
from ..studyspec.case import (
    ao_from,
    lgs_from,
    seeing_from,
    slope_noise_covariance_rad2,
    targets_from,
    telescope_from,
    tomography_from,
    wfs_from,
)
from ..tomography.reconstructor import factorize, reconstruction_points, target_reconstructor
from ..tomography.slopes import SlopeGeometry, slope_covariance

log = logging.getLogger(__name__)


def noise_covariance_rad2(spec: dict, settings, wfs, lgs) -> np.ndarray | None:
    """The slopes' NEA (``studyspec.case.slope_noise_covariance_rad2``) of a reconstructor or
    command-matrix spec that has the seeing of its spots (``studyspec.products.noise_seeing``), or None."""
    if "atmosphere" not in spec:
        return None
    return slope_noise_covariance_rad2(settings, wfs, lgs, seeing_from(spec["atmosphere"], lgs))


def build_reconstructors(spec: dict) -> xr.Dataset:
    """Reconstructors for every target of a ``studyspec.products.reconstructor_spec``."""
    telescope = telescope_from(spec["telescope"])
    lgs = lgs_from(spec["lgs"])
    settings = wfs_from(spec["wfs"])
    wfs = settings.shack_hartmann(telescope, lgs)
    tomography = tomography_from(spec["tomography"])
    prior, noise_rad = tomography.prior, tomography.noise_rms_rad
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    points = reconstruction_points(telescope, wfs.subaperture_m, tomography.points_per_subaperture)
    start = time.perf_counter()
    noise = noise_covariance_rad2(spec, settings, wfs, lgs)
    cholesky = factorize(slope_covariance(prior, geometry, noise_rad, noise_covariance_rad2=noise))
    log.info("%d slopes: covariance factorised in %.1f s", geometry.n_slopes, time.perf_counter() - start)
    matrices = []
    for target in targets_from(spec["targets_arcsec"]):
        direction = (target.theta_x_rad, target.theta_y_rad)
        matrices.append(target_reconstructor(prior, geometry, noise_rad, points, direction, cholesky_lower=cholesky))
    log.info("%d targets x %d points: built in %.1f s", len(matrices), len(points), time.perf_counter() - start)
    return xr.Dataset(
        {
            "reconstructor": (
                ("target", "point", "slope"),
                np.stack(matrices).astype(np.float32),
                {"units": "m rad-1", "long_name": "tilt-removed slopes to tilt-removed optical path along the target"},
            ),
            "point_x_m": ("point", points[:, 0], {"units": "m", "long_name": "reconstruction point x"}),
            "point_y_m": ("point", points[:, 1], {"units": "m", "long_name": "reconstruction point y"}),
        },
        attrs={"n_slopes": geometry.n_slopes, "build_seconds": time.perf_counter() - start},
    )


def build_commands(spec: dict) -> xr.Dataset:
    """The command matrix and the DM slopes of a ``studyspec.products.commands_spec``."""
    telescope = telescope_from(spec["telescope"])
    lgs = lgs_from(spec["lgs"])
    settings = wfs_from(spec["wfs"])
    wfs = settings.shack_hartmann(telescope, lgs)
    tomography = tomography_from(spec["tomography"])
    ao = ao_from(spec["ao"])
    dm = ao.deformable_mirror(telescope)
    geometry = SlopeGeometry.from_wfs(wfs, lgs)
    start = time.perf_counter()
    noise = noise_covariance_rad2(spec, settings, wfs, lgs)
    matrix = command_matrix(
        tomography.prior,
        geometry,
        tomography.noise_rms_rad,
        dm,
        ao.mode,
        ao.correction_direction_rad,
        ao.glao_max_height_m,
        cholesky_lower=None
        if noise is None
        else factorize(slope_covariance(tomography.prior, geometry, 0.0, noise_covariance_rad2=noise)),
    )
    log.info(
        "%s: %d actuators x %d slopes in %.1f s", ao.mode, dm.n_valid, geometry.n_slopes, time.perf_counter() - start
    )
    return xr.Dataset(
        {
            "command_matrix": (
                ("actuator", "slope"),
                matrix,
                {"units": "m rad-1", "long_name": "tilt-removed LGS slopes to DM commands (optical path)"},
            ),
            "dm_slopes": (
                ("slope", "actuator"),
                dm_slopes_matrix(dm, wfs, lgs.n_beacons),
                {"units": "rad m-1", "long_name": "tilt-removed slopes every LGS WFS sees per DM command"},
            ),
            "actuator_x_m": ("actuator", dm.actuator_xy_m[:, 0], {"units": "m", "long_name": "actuator x"}),
            "actuator_y_m": ("actuator", dm.actuator_xy_m[:, 1], {"units": "m", "long_name": "actuator y"}),
        },
        attrs={"n_slopes": geometry.n_slopes, "build_seconds": time.perf_counter() - start},
    )
