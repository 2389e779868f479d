"""Typed settings of a case's lucky imaging, unpacked from its dict once, here (beside
:mod:`.case`, which does the same for a case's physics).

The dict comes from ``config.lucky_settings`` (validated; defaults in ``config.schema.yaml``).
"""

from dataclasses import dataclass

from ..lucky.detector import Detector
from .case import Case
from .config import canonical_json, error_blocks, image_crop_px, imaged_targets


@dataclass(frozen=True)
class LuckySettings:
    """One case's lucky imaging: its detectors, fractions kept, time blocks of the errors, the
    detector-noise seed, the images' crop, and the case (its config for provenance, its physics, the targets the
    simulation imaged and the reference target, if any)."""

    case_name: str
    case_config: dict
    case: Case
    seed: int
    fractions: tuple[float, ...]
    detectors: tuple[Detector, ...]
    error_blocks: int
    imaged_targets: tuple[int, ...]
    reference_target: int | None
    image_crop_px: int | None
    """Pixels across the integrated images kept (None: the whole frame)."""
    settings_json: str
    """The settings but the case config, as canonical JSON (stored with the results)."""

    @classmethod
    def from_settings(cls, settings: dict) -> "LuckySettings":
        """From a ``config.lucky_settings`` dict."""
        case = settings["case_config"]
        return cls(
            case_name=settings["case"], case_config=case, case=Case.from_config(case), seed=settings["seed"],
            fractions=tuple(settings["fractions"]),
            detectors=tuple(Detector(name, d["photons_per_frame"], d["read_noise_e"])
                            for name, d in settings["detectors"].items()),
            error_blocks=error_blocks(settings), imaged_targets=tuple(imaged_targets(case)),
            reference_target=case.get("reference_target"), image_crop_px=image_crop_px(settings),
            settings_json=canonical_json({k: v for k, v in settings.items() if k != "case_config"}))
