"""Lucky post-processing of one case: frames + telemetry -> ``lucky.nc``.

Runs ``lucky.run_lucky`` for every target and detector (with a ``reference_target``,
the star's frames select and recentre every target), and adds what the
figures need from the telemetry: the long-exposure Strehl's Monte-Carlo error
(batch means of the per-frame value on the axis) and the mean r0.
"""

import json
import logging

import numpy as np
import xarray as xr

from ..lucky.detector import Detector
from ..lucky.selection import ExternalCriterion, ImageReference, run_lucky
from .case import Case
from .config import canonical_json, image_crop_px, imaged_targets
from .datasets import iter_frame_blocks, open_dataset, provenance, require_finite, write_dataset
from .simulation import replay_frames
from .turbulence import read_screens

log = logging.getLogger(__name__)

EXTERNAL_CRITERIA = (
    ("lgs_rms", "LGS tomographic (open-loop) tilt-removed rms along the target"),
    ("lgs_residual_rms", "LGS pseudo-closed-loop tilt-removed rms along the target"),
)
"""Selection criteria from the telemetry (smaller is better), when the case has them; with AO
also the oracle ``true_rms``, the true corrected tilt-removed rms (a bound, not observable)."""


def batch_mean_error(values: np.ndarray, n_blocks: int) -> float:
    """Standard error of the mean of a correlated series from ``n_blocks`` batch means
    (valid when blocks are longer than the correlation time)."""
    usable = len(values) // n_blocks * n_blocks
    means = np.asarray(values[:usable], dtype=float).reshape(n_blocks, -1).mean(axis=1)
    return float(means.std(ddof=1) / np.sqrt(n_blocks))


def _replayed(case: dict, telemetry: xr.Dataset, target: int, screens_path, screens_metadata_path):
    """The frames of one target replayed from the screens and the recorded DM commands,
    as ``iter_frame_blocks`` gives stored ones; each frame's value on the axis goes into
    the telemetry's ``axis_strehl`` as the simulation records it for the targets it images."""
    if not screens_path:
        raise ValueError(f"target {target} was not imaged by the simulation: its replay needs the screens")
    physics = Case.from_config(case)
    commands = telemetry["dm_commands_m"].values if "dm_commands_m" in telemetry else None
    replay = replay_frames(physics, read_screens(screens_path, screens_metadata_path), [target], commands)
    axis = telemetry["axis_strehl"].values[target]
    peak, centre = float(telemetry.attrs["diffraction_limited_peak"]), physics.camera.n_pixels // 2

    def iterate():
        for start, frames in replay():
            axis[start:start + frames.shape[1]] = frames[0, :, centre, centre] / peak
            yield start, frames[0]

    return iterate


def lucky_case(settings: dict, frames_path, telemetry_path, out_path, screens_path="",
               screens_metadata_path="") -> None:
    """Write one case's ``lucky.nc``; ``settings`` from ``config.lucky_settings``. The
    targets the simulation did not image (:func:`.config.imaged_targets`) are replayed
    from the screens with the recorded DM commands (:func:`.simulation.replay_frames`)."""
    telemetry = open_dataset(telemetry_path, "telemetry", allow_nan={"axis_strehl"})  # NaN: a target not imaged
    case = settings["case_config"]
    imaged = imaged_targets(case)
    detectors = [Detector(name, d["photons_per_frame"], d["read_noise_e"])
                 for name, d in settings["detectors"].items()]
    pixel_scale = Case.from_config(case).camera.pixel_scale_arcsec
    n_frames, n_targets = telemetry.sizes["frame"], telemetry.sizes["target"]
    n_blocks = settings["error_blocks"]
    reference = case.get("reference_target")
    order = list(range(n_targets)) if reference is None else [reference] + [
        t for t in range(n_targets) if t != reference]  # the star first: the others take its measurements
    per_target = {}
    for target in order:
        log.info("target %d/%d", target + 1, n_targets)
        external = [ExternalCriterion(name, telemetry[f"{name}_nm"].values[target], False, "nm", long_name)
                    for name, long_name in EXTERNAL_CRITERIA if f"{name}_nm" in telemetry]
        if "lgs_residual_rms_nm" in telemetry:
            external.append(ExternalCriterion("true_rms", telemetry.true_rms_nm.values[target], False, "nm",
                                              "true corrected tilt-removed rms along the target (oracle)"))
        image_reference = None if reference in (None, target) else ImageReference.of(per_target[reference])
        if target in imaged:
            frames = iter_frame_blocks(frames_path, target)
        else:
            frames = _replayed(case, telemetry, target, screens_path, screens_metadata_path)
        per_target[target] = run_lucky(
            frames, n_frames, detectors, settings["fractions"],
            float(telemetry.attrs["diffraction_limited_peak"]), pixel_scale, settings["seed"] + target,
            criteria_external=external, reference=image_reference, n_blocks=n_blocks,
            image_crop_px=image_crop_px(settings))
    ds = xr.concat([per_target[t] for t in range(n_targets)], dim="target", data_vars="all", coords="minimal",
                   compat="override")
    ds["reference_target"] = ((), -1 if reference is None else reference, {
        "units": "1", "long_name": "target whose frames give every target its image criteria and recentring "
                                  "(-1: each target its own)"})
    errors = [batch_mean_error(telemetry.axis_strehl.values[t], n_blocks) for t in range(ds.sizes["target"])]
    ds["long_exposure_strehl_error"] = ("target", errors, {
        "units": "1", "long_name": f"Monte-Carlo standard error of the long-exposure Strehl (no recentring), "
                                   f"from {n_blocks} batch means"})
    recentred = [[batch_mean_error(v, n_blocks) for v in ds.frame_recentred_strehl.values[t]]
                 for t in range(ds.sizes["target"])]
    ds["recentred_long_exposure_strehl_error"] = (("target", "detector"), recentred, {
        "units": "1", "long_name": f"Monte-Carlo standard error of the recentred long-exposure Strehl, "
                                   f"from {n_blocks} batch means"})
    for name in ("true_rms_nm", "lgs_rms_nm", "lgs_residual_rms_nm"):
        if name in telemetry:
            ds[name] = telemetry[name]
    ds["mean_r0_500nm_m"] = ((), float(telemetry.r0_500nm_m.mean()),
                             {"units": "m", "long_name": "mean Fried parameter at 500 nm over the case"})
    ds = ds.assign_coords(target_x_arcsec=telemetry.target_x_arcsec, target_y_arcsec=telemetry.target_y_arcsec)
    ds.attrs.update(provenance(f"luckyao lucky imaging of case {settings['case']}", case, settings["seed"]))
    ds.attrs["case"] = settings["case"]
    ds.attrs["lucky_settings_json"] = canonical_json({k: v for k, v in settings.items() if k != "case_config"})
    ds.attrs["telemetry_config_sha256"] = telemetry.attrs["config_sha256"]
    # A noisy image can have no positive flux (a few photons under read noise): its metrics
    # are undefined (NaN), per frame or integrated. Nothing else may be NaN: every value of
    # the noiseless detectors and every variable without a detector.
    noisy = [str(d) for d, n in zip(ds.detector.values, ds.photons_per_frame.values) if np.isfinite(n)]
    for name, var in ds.data_vars.items():
        if var.dtype.kind == "f" and not name.startswith("frame_"):
            strict = var.drop_sel(detector=noisy) if "detector" in var.dims else var
            require_finite(strict.values, f"file '{out_path}'", name, strict.dims)
    write_dataset(ds, out_path, allow_nan=set(ds.data_vars))
    log.info("wrote %s: %s", out_path, json.dumps({k: int(v) for k, v in ds.sizes.items()}))
