"""Registration of a field's science target on several stars (a case's ``stars``): the variables
``stars_*`` and ``star_*`` of its ``lucky.nc`` (:func:`stars_dataset`).

For each count ``n`` of ``stars.counts`` the science target's frames are selected on the
brightest star's image criteria (as the single-star field) and shifted to the inverse-variance
mean of the first ``n`` stars' positions (:mod:`luckyao.lucky.stars`), by each registration method
and detector; one star is the field's own single-star result (the same values). Each star's noise
variance is measured from its noisy and noiseless positions; the anisoplanatic variance comes from
the case's turbulence profile (:mod:`luckyao.atmosphere.tilt_anisoplanatism`), and is checked
against the differential tilt measured between the stars' and the target's noiseless centres of
gravity (``star_differential_tilt_variance_px2``).
"""

import logging
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import xarray as xr

from ..atmosphere.tilt_anisoplanatism import differential_tilt_variance_rad2
from ..lucky.detector import Detector
from ..lucky.pipeline import ImageReference, run_lucky_methods
from ..lucky.registration import COG
from ..lucky.stars import combined_positions, noise_variance_px2, star_positions, star_weights
from ..seeds import target_seed
from ..studyspec.lucky_settings import LuckySettings

log = logging.getLogger(__name__)

STARS_VARIABLES = ("strehl", "d50_arcsec", "fwhm_arcsec")
"""The science target's scores kept per count of stars, with their ``_noiseless`` and ``_error``."""


def _attrs(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


def stars_dataset(
    settings: LuckySettings,
    telemetry: xr.Dataset,
    per_target: dict,
    frames_of: Callable,
    lucky_kwargs: dict,
) -> xr.Dataset:
    """The case's several-star registration (module docstring): ``per_target`` the field's results
    (target -> one dataset per registration method, as ``steps.postprocess``), ``frames_of(target)``
    a target's frame chunks, ``lucky_kwargs`` the arguments of its science target's
    :func:`.pipeline.run_lucky_methods` but the references."""
    spec = settings.case_config["stars"]
    stars, ratios, science = list(spec["targets"]), list(spec["flux_ratio"]), spec["science_target"]
    n_frames = telemetry.sizes["frame"]
    registrations = settings.registration_methods()
    detectors = list(settings.detectors)
    noiseless = next(i for i, d in enumerate(detectors) if d.noiseless)
    cog = settings.registrations.index("cog")
    positions = []
    for star, ratio in zip(stars, ratios):
        log.info("stars: the positions of star %d (target %d, flux ratio %g)", len(positions) + 1, star, ratio)
        scaled = _scaled(detectors, ratio)
        seed = target_seed(settings.seed, star)
        positions.append(star_positions(frames_of(star), n_frames, scaled, seed, registrations))
    positions = np.stack(positions)  # (star, method, detector, frame, 2)
    truth = star_positions(frames_of(science), n_frames, [Detector("noiseless")], 0, [COG])[0, 0]  # (frame, 2)
    measured = np.nanvar(positions[:, cog, noiseless] - truth, axis=1)  # (star, 2) y, x
    targets = np.asarray(settings.case_config["targets_arcsec"], dtype=float)
    separation = targets[stars] - targets[science]  # (star, 2) x, y [arcsec]
    atmosphere, telescope = settings.case_config["atmosphere"], settings.case_config["telescope"]
    theory = (
        differential_tilt_variance_rad2(
            separation,
            atmosphere["height_m"],
            atmosphere["cn2_fraction"],
            float(telemetry.r0_500nm_m.mean()),
            atmosphere["outer_scale_m"],
            telescope["diameter_m"],
            telescope["obscuration_m"],
        )[:, ::-1]
        / settings.case.camera.pixel_scale_rad**2
    )  # (star, 2) y, x [pixel^2]
    noise = noise_variance_px2(positions, positions[:, :, noiseless : noiseless + 1])  # (star, method, detector, 2)
    aniso = theory[:, None, None, :]
    reference = per_target[stars[0]]
    results = []
    for n in spec["counts"]:
        if n == 1:  # the field's single-star result
            results.append(per_target[science])
            continue
        combined = combined_positions(positions[:n], star_weights(noise[:n], aniso[:n]))  # (method, detector, frame, 2)
        references = [
            ImageReference(ds.frame_strehl.values, ds.frame_d50_arcsec.values, combined[m])
            for m, ds in enumerate(reference)
        ]
        log.info("stars: the science target (target %d) registered on %d stars", science, n)
        results.append(run_lucky_methods(frames_of(science), n_frames, references=references, **lucky_kwargs))
    return _dataset(spec, results, separation, measured, theory, noise)


def _scaled(detectors: list[Detector], ratio: float) -> list[Detector]:
    """The detectors of a star ``ratio`` times as bright as the brightest (the same names: its noise
    is keyed by its own target's seed)."""
    return [d if d.noiseless else replace(d, photons_per_frame=d.photons_per_frame * ratio) for d in detectors]


def _dataset(spec, results, separation, measured, theory, noise) -> xr.Dataset:
    counts = list(spec["counts"])
    data = {}
    for name in STARS_VARIABLES:
        for suffix in ("", "_noiseless", "_error"):
            if f"{name}{suffix}" not in results[0][0]:
                continue
            var = xr.concat(
                [xr.concat([ds[f"{name}{suffix}"] for ds in per_method], dim="registration") for per_method in results],
                dim="n_stars",
            )
            attrs = dict(var.attrs)
            attrs["long_name"] = f"{attrs.get('long_name', name)}, science target registered on n_stars stars"
            data[f"stars_{name}{suffix}"] = var.assign_attrs(attrs)
    ds = xr.Dataset(data).assign_coords(
        n_stars=("n_stars", counts, _attrs("1", "stars registered on: the first n of stars.targets")),
    )
    ds["star_target"] = ("star", list(spec["targets"]), _attrs("1", "index in targets_arcsec of the star"))
    ds["star_flux_ratio"] = ("star", list(spec["flux_ratio"]), _attrs("1", "star's flux over the brightest's"))
    ds["star_separation_arcsec"] = (
        ("star", "axis"),
        separation[:, ::-1],
        _attrs("arcsec", "star's direction less the science target's"),
    )
    ds["star_differential_tilt_variance_px2"] = (
        ("star", "axis"),
        measured,
        _attrs("1", "variance [pixel^2] of the star's noiseless centre of gravity less the science target's"),
    )
    ds["star_differential_tilt_variance_theory_px2"] = (
        ("star", "axis"),
        theory,
        _attrs(
            "1",
            "tilt anisoplanatism [pixel^2]: the differential G-tilt variance of the case's turbulence profile "
            "at the mean r0 (the star's weight's anisoplanatic term)",
        ),
    )
    ds["star_noise_variance_px2"] = (
        ("registration", "star", "detector", "axis"),
        noise.transpose(1, 0, 2, 3),
        _attrs("1", "mean square [pixel^2] of the star's noisy less noiseless positions (its weight's noise term)"),
    )
    ds.attrs["science_target"] = spec["science_target"]
    return ds
