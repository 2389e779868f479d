"""Typed settings of a case's lucky imaging, unpacked from its dict once, here (beside
:mod:`.case`, which does the same for a case's physics).

The dict comes from ``studyspec.lucky.lucky_settings`` (validated; defaults in ``studyspec/schema.yaml``).
"""

from dataclasses import dataclass

import numpy as np

from ..io.hashing import canonical_json
from ..lucky.cropped import crop_px
from ..lucky.detector import Detector
from ..lucky.metrics import EncircledEnergy, d50_from_radius, fwhm_arcsec
from ..lucky.registration import Registration, search_px
from ..lucky.scoring import MatchedStrehl
from ..optics.imaging import Imager
from .case import Case
from .lucky import error_blocks, frame_strehl, image_crop_px, registrations
from .resolved import imaged_targets


def shared_image_crop_px(configured: int | None, methods, camera) -> int | None:
    """The integrated images' crop every registration method can keep: ``lucky.image_crop_px``
    (None: the whole frame; 0: no images), at most a sub-pixel method's crop when one runs
    (:func:`luckyao.lucky.cropped.crop_px`, 1.25": 40 pixels at 2.5 m against 64, 64 at 4.2 m),
    so that the methods' images share one square along ``lucky.nc``'s registration."""
    if configured == 0 or all(name == "cog" for name in methods):
        return configured
    held = crop_px(camera.n_pixels, camera.pixel_scale_arcsec)
    return held if configured is None else min(configured, held)


@dataclass(frozen=True)
class LuckySettings:
    """One case's lucky imaging: its detectors, fractions kept, time blocks of the errors, the
    detector-noise seed, the images' crop, the registration methods, and the case (its config for provenance, its
    physics, the targets the
    simulation imaged and the reference target, if any)."""

    case_name: str
    case_config: dict
    case: Case
    seed: int
    fractions: tuple[float, ...]
    detectors: tuple[Detector, ...]
    error_blocks: int
    imaged_targets: tuple[int, ...]
    """The targets whose frames the simulation stored (none with ``replay_frames``: each is replayed)."""
    reference_target: int | None
    image_crop_px: int | None
    """Pixels across the integrated images kept (None: the whole frame; 0: none), the same for
    every registration method (:func:`shared_image_crop_px`)."""
    registrations: tuple[str, ...]
    """The registration methods (:mod:`luckyao.lucky.registration`), ``cog`` among them."""
    frame_strehl: str
    """A frame's Strehl: ``peak_pixel`` or ``matched_filter`` (:class:`luckyao.lucky.scoring.MatchedStrehl`)."""
    settings_json: str
    """The settings but the case config, as canonical JSON (stored with the results)."""
    fourier_fractions: tuple[float, ...] | None = None
    """The fractions of Fourier lucky imaging (:mod:`luckyao.lucky.fourier`), or None: not for this case."""

    @classmethod
    def from_settings(cls, settings: dict) -> "LuckySettings":
        """From a ``studyspec.lucky.lucky_settings`` dict."""
        case = settings["case_config"]
        physics = Case.from_config(case)
        return cls(
            case_name=settings["case"],
            case_config=case,
            case=physics,
            seed=settings["seed"],
            fractions=tuple(settings["fractions"]),
            detectors=tuple(
                Detector(
                    name,
                    d["photons_per_frame"],
                    d["read_noise_e"],
                    d.get("electron_multiplying", False),
                    d.get("photon_counting_threshold_e"),
                )
                for name, d in settings["detectors"].items()
            ),
            error_blocks=error_blocks(settings),
            imaged_targets=() if settings.get("replay_frames", False) else tuple(imaged_targets(case)),
            reference_target=case.get("reference_target"),
            image_crop_px=shared_image_crop_px(image_crop_px(settings), registrations(settings), physics.camera),
            registrations=tuple(registrations(settings)),
            frame_strehl=frame_strehl(settings),
            settings_json=canonical_json({k: v for k, v in settings.items() if k != "case_config"}),
            fourier_fractions=tuple(settings["fourier_fractions"]) if "fourier_fractions" in settings else None,
        )

    def registration_methods(self) -> list[Registration]:
        """The registration methods, built for the case's camera: the diffraction-limited image
        (``xcorr``'s reference), the core's FWHM, lambda/D [pixel] (the matched filter) and the
        search box (:func:`luckyao.lucky.registration.search_px`)."""
        camera = self.case.camera
        box = search_px(camera.n_pixels, camera.pixel_scale_arcsec)
        return [
            Registration(name, self._diffraction_limited(), self._core_fwhm_px(), box) for name in self.registrations
        ]

    def matched_strehl(self) -> MatchedStrehl | None:
        """The frames' matched-filter Strehl (``frame_strehl: matched_filter``), else None."""
        if self.frame_strehl != "matched_filter":
            return None
        return MatchedStrehl.of(self._diffraction_limited(), self._core_fwhm_px())

    def diffraction_limited_scores(self) -> tuple[float, float]:
        """FWHM and d50 [arcsec] of the unit-flux diffraction-limited image at the camera's
        sampling, by the measures that score the integrated images (:func:`luckyao.lucky.metrics.fwhm_arcsec`,
        the encircled energy about its centre of gravity): the limits no image passes
        (:func:`luckyao.lucky.limits.beyond_diffraction_limit`)."""
        image = self._diffraction_limited().astype(np.float64)
        scale = self.case.camera.pixel_scale_arcsec
        radius = EncircledEnergy(image.shape[-1]).radius_px(image[None])[0]
        return float(fwhm_arcsec(image, scale)), float(d50_from_radius(radius, scale))

    def _diffraction_limited(self):
        return Imager(self.case.telescope, self.case.camera).diffraction_limited

    def _core_fwhm_px(self) -> float:
        """lambda / D [pixel], the diffraction-limited core's FWHM (1.03 lambda/D unobscured; less obscured)."""
        camera = self.case.camera
        return camera.wavelength_m / self.case.telescope.diameter_m / camera.pixel_scale_rad
