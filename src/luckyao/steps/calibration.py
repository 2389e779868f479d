"""The cached WFS calibration product and a case's slope estimator.

* Calibration: from a ``studyspec.products.calibration_spec`` (sensor, estimator, mean seeing,
  seed), each sub-aperture's 2 x 2 slope response measured by push-pull dithers
  through the physical-optics sensor (:func:`luckyao.wfs.calibration.measure_response`),
  with the standard error of its mean.
* :func:`slope_estimator`: a case's centroider (``wfs.centroider``) and, with
  ``wfs.calibration``, its calibrated response.
"""

import logging
import time

import xarray as xr

from ..seeds import calibration_rng
from ..studyspec.case import Case, WfsSettings, lgs_from, seeing_from, telescope_from, wfs_from
from ..wfs.calibration import SlopeResponse, measure_response, reference_spot_spectra
from ..wfs.centroiders import SlopeEstimator, make_centroider
from ..wfs.shack_hartmann import ShackHartmann, lgs_elongation_otf

log = logging.getLogger(__name__)


def case_centroider(settings: WfsSettings, wfs: ShackHartmann, elongation, seeing):
    """The centroider of a case's WFS settings (the correlation's reference: the
    long-exposure spot of the case's mean seeing)."""
    reference = reference_spot_spectra(wfs, elongation, seeing) if settings.centroider == "correlation" else None
    return make_centroider(settings.centroider, wfs, settings.threshold, reference)


def build_calibration(spec: dict) -> xr.Dataset:
    """The slope response of a ``studyspec.products.calibration_spec``."""
    telescope, lgs = telescope_from(spec["telescope"]), lgs_from(spec["lgs"])
    settings = wfs_from({"photons_per_subaperture": None, "read_noise_e": 0.0, "exposure_steps": 1, **spec["wfs"]})
    wfs = settings.shack_hartmann(telescope, lgs)
    elongation = lgs_elongation_otf(wfs, lgs)
    seeing = seeing_from(spec["atmosphere"], lgs)
    centroider = case_centroider(settings, wfs, elongation, seeing)
    start = time.perf_counter()
    response = measure_response(
        wfs,
        elongation,
        seeing,
        centroider,
        min(lgs.n_beacons, 4),
        settings.calibration_draws,
        calibration_rng(spec["seed"]),
    )
    seconds = time.perf_counter() - start
    log.info(
        "%d sub-apertures, %s: mean gains x %.3f, y %.3f (+- %.3f) in %.1f s",
        wfs.n_valid,
        settings.centroider,
        response.matrix[0, 0].mean(),
        response.matrix[1, 1].mean(),
        response.matrix_error[0, 0].mean(),
        seconds,
    )
    axes = {
        "output": ("output", ["x", "y"], {"long_name": "measured slope axis"}),
        "input": ("input", ["x", "y"], {"long_name": "wavefront slope axis"}),
    }
    return xr.Dataset(
        {
            "response": (
                ("output", "input", "subaperture"),
                response.matrix,
                {
                    "units": "1",
                    "long_name": "measured slope per mean wavefront slope over the sub-aperture, "
                    "mean over turbulence draws and beacons",
                },
            ),
            "response_error": (
                ("output", "input", "subaperture"),
                response.matrix_error,
                {"units": "1", "long_name": "standard error of the mean response"},
            ),
            "subaperture_x_m": ("subaperture", wfs.subaperture_xy_m[:, 0], {"units": "m", "long_name": "centre x"}),
            "subaperture_y_m": ("subaperture", wfs.subaperture_xy_m[:, 1], {"units": "m", "long_name": "centre y"}),
        },
        coords={k: (v[0], v[1], v[2]) for k, v in axes.items()},
        attrs={
            "draws": settings.calibration_draws,
            "beacons_per_draw": min(lgs.n_beacons, 4),
            "build_seconds": seconds,
        },
    )


def slope_estimator(case: Case, wfs: ShackHartmann, elongation, calibration: xr.Dataset | None) -> SlopeEstimator:
    """The case's images -> slopes: its centroider, with the calibrated ``response`` of
    ``calibration`` (:func:`build_calibration`) when ``wfs.calibration`` asks for it."""
    centroider = case_centroider(case.wfs, wfs, elongation, case.seeing)
    if case.wfs.calibration == "none":
        return SlopeEstimator(centroider)
    if calibration is None:
        raise ValueError(f"wfs.calibration: {case.wfs.calibration} needs the calibration product")
    if calibration.sizes["subaperture"] != wfs.n_valid:
        raise ValueError("the calibration does not match this WFS: rebuild it")
    return SlopeEstimator(centroider, SlopeResponse(calibration["response"].values))
