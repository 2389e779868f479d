"""Lucky post-processing of one case: frames + telemetry -> ``lucky.nc``.

Runs ``lucky.run_lucky_methods`` for every target, detector and registration method (the
methods in the same passes over a target's frames; with a ``reference_target``, the star's
frames select and recentre every target, by each method), and adds what the
figures need from the telemetry: the long-exposure Strehl's Monte-Carlo error
(batch means of the per-frame value on the axis) and the mean r0.
"""

import json
import logging

import numpy as np
import xarray as xr

from ..ao.laser_criteria import FRAME_CRITERIA, TARGET_CRITERIA
from ..io.datasets import iter_frame_blocks, open_dataset, provenance, require_finite_lucky, write_dataset
from ..lucky.accumulation import batch_mean_error
from ..lucky.dataset import add_noise_flags
from ..lucky.limits import add_limit_flags
from ..lucky.pipeline import ImageReference, run_lucky_methods
from ..lucky.ranking import ExternalCriterion
from ..seeds import target_seed
from ..studyspec.lucky import by_signal
from ..studyspec.lucky_settings import LuckySettings
from .learned import learned_rms_nm
from .screens import read_screens
from .simulation import Replay
from .stars import stars_dataset

log = logging.getLogger(__name__)

EXTERNAL_CRITERIA = (
    ("lgs_rms", "LGS tomographic (open-loop) tilt-removed rms along the target"),
    ("lgs_residual_rms", "LGS pseudo-closed-loop tilt-removed rms along the target"),
    *TARGET_CRITERIA,
    *FRAME_CRITERIA,
)
"""Selection criteria from the telemetry (smaller is better), when the case has them (the laser
criteria with ``ao.laser_criteria``); with AO also the oracle ``true_rms``, the true corrected
tilt-removed rms (a bound, not observable), and with a learned model (``ao.learned_training_seed``)
``learned``, its prediction (:mod:`.learned`)."""


CHUNK_FRAMES = 64
"""Frames per chunk fed to the lucky pipeline, read from a cube or replayed alike: its guessed bins
(and so which noisy frames are drawn again, their sums to float64 rounding) follow the chunking."""


def _frames_of(
    settings: LuckySettings, telemetry: xr.Dataset, target: int, frames_path, screens_path, screens_metadata_path
):
    """A target's frames for :func:`.pipeline.run_lucky_methods`: stored, or replayed from the screens and
    the recorded DM commands (:class:`.simulation.Replay`, whose values on the axis the caller
    reads once they are made); the replay, or None."""
    if target in settings.imaged_targets:
        return iter_frame_blocks(frames_path, target, CHUNK_FRAMES), None
    if not screens_path:
        raise ValueError(f"target {target} was not imaged by the simulation: its replay needs the screens")
    commands = telemetry["dm_commands_m"].values if "dm_commands_m" in telemetry else None
    replay = Replay(settings.case, read_screens(screens_path, screens_metadata_path), [target], commands, CHUNK_FRAMES)

    def iterate():
        for start, frames in replay():
            yield start, frames[0]

    return iterate, replay


def _external_criteria(telemetry: xr.Dataset, target: int, model: xr.Dataset | None = None) -> list[ExternalCriterion]:
    """The target's selection criteria from the telemetry (:data:`EXTERNAL_CRITERIA`, the
    oracle, and with a learned ``model`` its prediction)."""
    external = [
        ExternalCriterion(name, _of_target(telemetry[f"{name}_nm"], target), False, "nm", long_name)
        for name, long_name in EXTERNAL_CRITERIA
        if f"{name}_nm" in telemetry
    ]
    if model is not None:
        external.append(
            ExternalCriterion(
                "learned",
                learned_rms_nm(model, telemetry, target),
                False,
                "nm",
                f"true rms predicted from the laser telemetry (ridge, trained on seed {model.attrs['training_seed']})",
            )
        )
    if "lgs_residual_rms_nm" in telemetry:
        external.append(
            ExternalCriterion(
                "true_rms",
                telemetry.true_rms_nm.values[target],
                False,
                "nm",
                "true corrected tilt-removed rms along the target (oracle)",
            )
        )
    return external


def _of_target(variable: xr.DataArray, target: int) -> np.ndarray:
    """A telemetry variable's values (frame,) of a target: its own, or the frame's (no target axis)."""
    return variable.values[target] if "target" in variable.dims else variable.values


def _lucky_arguments(
    settings: LuckySettings, telemetry: xr.Dataset, target: int, peak: float, model: xr.Dataset | None = None
) -> dict:
    """A target's :func:`.pipeline.run_lucky_methods` arguments but its frames and references."""
    return dict(
        detectors=settings.detectors,
        fractions=settings.fractions,
        diffraction_limited_peak=peak,
        pixel_scale_arcsec=settings.case.camera.pixel_scale_arcsec,
        seed=target_seed(settings.seed, target),
        criteria_external=_external_criteria(telemetry, target, model),
        n_blocks=settings.error_blocks,
        image_crop_px=settings.image_crop_px,
        registrations=settings.registration_methods(),
        matched_strehl=settings.matched_strehl(),
        fourier_fractions=settings.fourier_fractions,
    )


def lucky_case(
    settings_config: dict,
    frames_path,
    telemetry_path,
    out_path,
    screens_path="",
    screens_metadata_path="",
    learned_path="",
) -> None:
    """Write one case's ``lucky.nc``; ``settings_config`` from ``studyspec.lucky.lucky_settings``. The
    targets the simulation did not image (:func:`luckyao.studyspec.resolved.imaged_targets`) are replayed
    from the screens with the recorded DM commands (:class:`.simulation.Replay`). ``learned_path``: the
    case's learned model (:func:`.learned.train_model`), which gives the criterion ``learned``."""
    settings = LuckySettings.from_settings(settings_config)
    telemetry = open_dataset(telemetry_path, "telemetry", allow_nan={"axis_strehl"})  # NaN: a target not imaged
    model = open_dataset(learned_path, "learned model", allow_nan=()) if learned_path else None
    n_frames, n_targets = telemetry.sizes["frame"], telemetry.sizes["target"]
    n_blocks, reference = settings.error_blocks, settings.reference_target
    peak = float(telemetry.attrs["diffraction_limited_peak"])
    axis_strehl = telemetry.axis_strehl.values.copy()  # (target, frame); the replayed targets' filled below
    order = (
        list(range(n_targets)) if reference is None else [reference] + [t for t in range(n_targets) if t != reference]
    )  # the star first: the others take its measurements
    per_target = {}  # target -> its datasets, one per registration method (all made in the same passes)
    for target in order:
        log.info("target %d/%d, registration %s", target + 1, n_targets, ", ".join(settings.registrations))
        references = None if reference in (None, target) else [ImageReference.of(ds) for ds in per_target[reference]]
        frames, replay = _frames_of(settings, telemetry, target, frames_path, screens_path, screens_metadata_path)
        per_target[target] = run_lucky_methods(
            frames, n_frames, references=references, **_lucky_arguments(settings, telemetry, target, peak, model)
        )
        if replay is not None:
            axis_strehl[target] = replay.axis_strehl[0]
    per_registration = [
        xr.concat(
            [per_target[t][m] for t in range(n_targets)],
            dim="target",
            data_vars="all",
            coords="minimal",
            compat="override",
        )
        for m in range(len(settings.registrations))
    ]
    ds = xr.concat(per_registration, dim="registration", data_vars="all", coords="minimal", compat="override")
    ds = ds.assign_coords(
        registration=(
            "registration",
            list(settings.registrations),
            {
                "units": "1",
                "long_name": "registration method of the frames (recentring 'cog' of the long exposure: "
                "registered by this method)",
            },
        )
    )
    ds.attrs.pop("frames_drawn_again", None)  # per target: in its log line
    if "stars" in settings.case_config:  # the science target registered on several stars

        def frames_of(target):
            return _frames_of(settings, telemetry, target, frames_path, screens_path, screens_metadata_path)[0]

        science = settings.case_config["stars"]["science_target"]
        arguments = _lucky_arguments(settings, telemetry, science, peak, model)
        ds = ds.merge(stars_dataset(settings, telemetry, per_target, frames_of, arguments))
    add_noise_flags(ds)  # where a noisy detector's scores are noise-dominated
    fwhm_dl, d50_dl = settings.diffraction_limited_scores()
    ds.attrs.update(diffraction_limited_fwhm_arcsec=fwhm_dl, diffraction_limited_d50_arcsec=d50_dl)
    add_limit_flags(ds)  # values beyond the diffraction limit, d50 set by the field
    # computed in the settings' order (names as text: a detector's last bits depend on its place
    # in the stacks the BLAS products score), stored by signal
    ds = ds.sel(detector=by_signal(settings_config["detectors"]))
    ds["reference_target"] = (
        (),
        -1 if reference is None else reference,
        {
            "units": "1",
            "long_name": "target whose frames give every target its image criteria and recentring "
            "(-1: each target its own)",
        },
    )
    errors = [batch_mean_error(axis_strehl[t], n_blocks) for t in range(ds.sizes["target"])]
    ds["long_exposure_strehl_error"] = (
        "target",
        errors,
        {
            "units": "1",
            "long_name": f"Monte-Carlo standard error of the long-exposure Strehl (no recentring), "
            f"from {n_blocks} batch means",
        },
    )
    values = ds.frame_recentred_strehl.transpose("registration", "target", "detector", "frame").values
    recentred = np.apply_along_axis(batch_mean_error, -1, values, n_blocks)  # (registration, target, detector)
    ds["recentred_long_exposure_strehl_error"] = (
        ("registration", "target", "detector"),
        recentred,
        {
            "units": "1",
            "long_name": f"Monte-Carlo standard error of the recentred long-exposure Strehl, "
            f"from {n_blocks} batch means",
        },
    )
    laser = [f"{name}_nm" for name, _ in TARGET_CRITERIA + FRAME_CRITERIA]
    for name in ("true_rms_nm", "lgs_rms_nm", "lgs_residual_rms_nm", "transmitted_flux", *laser):
        if name in telemetry:
            ds[name] = telemetry[name]
    for name in telemetry.data_vars:  # the residual budget's parts (ao.residual_budget)
        if name.startswith("residual_"):
            ds[name] = telemetry[name]
    ds["mean_r0_500nm_m"] = (
        (),
        float(telemetry.r0_500nm_m.mean()),
        {"units": "m", "long_name": "mean Fried parameter at 500 nm over the case"},
    )
    ds = ds.assign_coords(target_x_arcsec=telemetry.target_x_arcsec, target_y_arcsec=telemetry.target_y_arcsec)
    ds.attrs.update(
        provenance(f"luckyao lucky imaging of case {settings.case_name}", settings.case_config, settings.seed)
    )
    ds.attrs["case"] = settings.case_name
    ds.attrs["lucky_settings_json"] = settings.settings_json
    ds.attrs["telemetry_config_sha256"] = telemetry.attrs["config_sha256"]
    # NaN only where a noisy image has no positive flux (the rule every reader checks again)
    require_finite_lucky(ds, f"file '{out_path}'")
    write_dataset(ds, out_path, allow_nan=set(ds.data_vars))
    log.info("wrote %s: %s", out_path, json.dumps({k: int(v) for k, v in ds.sizes.items()}))
