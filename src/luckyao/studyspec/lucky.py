"""The lucky post-processing keys of a study (``lucky``): their defaults from the schema, the
detector sweep's named detectors, and the settings one case's lucky job uses."""

import numpy as np

from .schema import load_schema

SIGNAL_KINDS = ("quality_vs_signal", "registration", "limiting_magnitude", "more_stars")
"""The figure kinds drawn against the detector sweep: each case they draw must be one of
``lucky.detector_sweep.cases`` (``study.validate_study``)."""

MAGNITUDE_KINDS = ("registration", "limiting_magnitude", "more_stars")
"""The figure kinds that draw magnitudes: their settings carry the study's ``photometry``
(:func:`luckyao.photometry.config_with_defaults`), so that only they are redrawn when it changes."""


def _lucky_value(lucky: dict, key: str):
    """``lucky[key]``, by default the schema's default of that key."""
    return lucky.get(key, load_schema()["properties"]["lucky"]["properties"][key]["default"])


def image_crop_px(lucky: dict) -> int | None:
    """Pixels across the images ``lucky.nc`` keeps: ``lucky.image_crop_px``, by default the
    schema's (64); None: the whole frame."""
    return _lucky_value(lucky, "image_crop_px")


def error_blocks(lucky: dict) -> int:
    """Time blocks for the Monte-Carlo errors: ``lucky.error_blocks``, by default the schema's."""
    return _lucky_value(lucky, "error_blocks")


def frame_strehl(lucky: dict) -> str:
    """How a frame's Strehl is measured: ``lucky.frame_strehl``, by default the schema's (``peak_pixel``)."""
    return _lucky_value(lucky, "frame_strehl")


def registrations(lucky: dict) -> list[str]:
    """The registration methods: ``lucky.registration``, by default the schema's (``cog`` only)."""
    return list(_lucky_value(lucky, "registration"))


def fourier_cases(lucky: dict) -> list[str]:
    """The cases given Fourier lucky imaging: ``lucky.fourier.cases``, by default none."""
    return list(_fourier_value(lucky, "cases"))


def fourier_fractions(lucky: dict) -> list[float]:
    """The fractions of Fourier lucky imaging: ``lucky.fourier.fractions``, by default the schema's."""
    return [float(f) for f in _fourier_value(lucky, "fractions")]


def _fourier_value(lucky: dict, key: str):
    defaults = load_schema()["properties"]["lucky"]["properties"]["fourier"]["properties"]
    return lucky.get("fourier", {}).get(key, defaults[key]["default"])


MAX_SWEEP_DETECTORS = 1000
"""Most detectors of a detector sweep (read noises x levels; the paper's: 18)."""


def sweep_detector_list(lucky: dict) -> list[tuple[str, dict]]:
    """(name, detector) of every point of ``lucky.detector_sweep`` (none without it), in order:
    every read noise x ``levels`` photon counts per frame, log-spaced from ``min`` to ``max``."""
    sweep = lucky.get("detector_sweep")
    if sweep is None:
        return []
    grid = sweep["photons_per_frame"]
    photons = np.geomspace(grid["min"], grid["max"], grid["levels"])
    return [
        (sweep_name(read_noise, n), {"photons_per_frame": float(n), "read_noise_e": float(read_noise)})
        for read_noise in sweep["read_noise_e"]
        for n in photons
    ]


def sweep_detectors(lucky: dict) -> dict:
    """The named detectors of ``lucky.detector_sweep`` (:func:`sweep_detector_list`; their
    names distinct and none of ``lucky.detectors``'s: ``study.validate_study``)."""
    return dict(sweep_detector_list(lucky))


def sweep_cases(lucky: dict) -> list[str]:
    """The cases given the detector sweep and every registration method:
    ``lucky.detector_sweep.cases``, by default the schema's (none); none without a sweep."""
    sweep = lucky.get("detector_sweep")
    if sweep is None:
        return []
    default = load_schema()["properties"]["lucky"]["properties"]["detector_sweep"]["properties"]["cases"]["default"]
    return list(sweep.get("cases", default))


def by_signal(detectors: dict) -> list[str]:
    """The names of ``detectors`` (name -> detector) in the order of ``lucky.nc``'s ``detector``:
    the noiseless first, then by read noise and, within one, by detected photons per frame
    (``rn0.1_10ph`` before ``rn0.1_100ph``, not as text); ties by name. The settings reach the
    job as canonical JSON, its keys sorted as text: the job computes in that order (a detector's
    values depend on its place in the stacks, in their last bits) and stores in this one."""

    def signal(name: str) -> tuple:
        photons = detectors[name]["photons_per_frame"]
        return (photons is not None, detectors[name]["read_noise_e"], photons or 0.0, name)

    return sorted(detectors, key=signal)


def sweep_name(read_noise_e: float, photons_per_frame: float) -> str:
    return f"rn{read_noise_e:g}_{photons_per_frame:.3g}ph"


def lucky_settings(study: dict, cases: dict, case_name: str) -> dict:
    """The post-processing settings one case's lucky job uses, with its resolved config:
    every listed detector, and the detector sweep and every registration method when the case
    is one of ``lucky.detector_sweep.cases`` (:func:`sweep_cases`: their cost goes only where
    the config asks; elsewhere ``cog`` alone), whatever figures the study draws; with
    ``replay_frames``, the flag that every target's frames are made again from the screens (no
    cube); with Fourier lucky imaging (:func:`fourier_cases`), its fractions ``fourier_fractions`` (only
    then: the other cases' settings, and their hash, unchanged)."""
    lucky = {
        key: value for key, value in study["lucky"].items() if key not in ("detector_sweep", "registration", "fourier")
    }
    lucky["error_blocks"] = error_blocks(study["lucky"])
    lucky["registration"] = ["cog"]
    if case_name in sweep_cases(study["lucky"]):
        lucky["detectors"] = {**lucky["detectors"], **sweep_detectors(study["lucky"])}
        lucky["registration"] = registrations(study["lucky"])
    if case_name in fourier_cases(study["lucky"]):
        lucky["fourier_fractions"] = fourier_fractions(study["lucky"])
    if study.get("replay_frames", False):  # only when set: the settings (and their hash) of a stored cube unchanged
        lucky["replay_frames"] = True
    return {"seed": study["seed"], "case": case_name, "case_config": cases[case_name], **lucky}
