"""The CF-style dataset of a lucky-imaging run (:func:`.pipeline.run_lucky`). Its units are
UDUNITS-2's: a count (photons, electrons, pixels) is ``1``, what it counts said in ``long_name``."""

import numpy as np
import xarray as xr

from .accumulation import TimeBlocks, block_error

NOISE_DOMINATED = 0.3
"""A noisy detector's value is noise-dominated when it departs from the value of the same
selection and shifts applied to the noiseless frames by more than this fraction of it."""

NOISE_METRICS = ("strehl", "fwhm_arcsec", "d50_arcsec")
"""The integrated image's metrics flagged ``<metric>_noise_dominated`` (:func:`add_noise_flags`)."""


MEASURED = (
    "(a noisy detector's: what a pipeline measures, a Strehl ratio over the frames' expected flux, N photons "
    "a frame; the noiseless detector's: the ideal camera's)"
)
"""What a noisy detector's values are, said in their ``long_name``."""


def _attrs(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


def noise_dominated(value, clean):
    """Where ``value`` departs from ``clean`` (the same selection and shifts applied to the
    noiseless frames) by more than :data:`NOISE_DOMINATED` of it; NaN values are flagged."""
    return ~(np.abs(value - clean) <= NOISE_DOMINATED * np.abs(clean))


def noise_flag_attrs(metric: str) -> dict:
    """The CF attributes of ``<metric>_noise_dominated``."""
    return {
        **_attrs(
            "1",
            f"1 where {metric} departs by more than {NOISE_DOMINATED:.0%} from the same selection on the "
            "noiseless frames (noise-dominated: a noisy detector's Strehl above 1, for one)",
        ),
        "flag_values": np.array([0, 1], np.int8),
        "flag_meanings": "signal_dominated noise_dominated",
    }


def add_noise_flags(ds: xr.Dataset) -> None:
    """``<metric>_noise_dominated`` (int8, :func:`noise_dominated`) beside each of
    :data:`NOISE_METRICS` (and its Fourier lucky imaging's ``fourier_<metric>``) that has its
    noiseless counterpart ``<metric>_noiseless``."""
    for metric in [*NOISE_METRICS, *(f"fourier_{metric}" for metric in NOISE_METRICS)]:
        if f"{metric}_noiseless" in ds:
            flags = noise_dominated(ds[metric], ds[f"{metric}_noiseless"]).astype(np.int8)
            ds[f"{metric}_noise_dominated"] = flags.transpose(*ds[metric].dims).assign_attrs(noise_flag_attrs(metric))


def crop(images: np.ndarray, crop_px: int | None) -> np.ndarray:
    """Central ``crop_px`` square around pixel (n/2, n/2) of images (..., n, n)."""
    n = images.shape[-1]
    if crop_px is None or crop_px >= n:
        return images
    lo = n // 2 - crop_px // 2
    return images[..., lo : lo + crop_px, lo : lo + crop_px]


def result_dataset(
    detectors,
    criteria,
    criteria_external,
    fractions,
    counts,
    n_frames,
    s_int,
    fwhm_int,
    d50_int,
    s_long,
    fwhm_long,
    d50_long,
    frame_strehl,
    frame_d50_arcsec,
    frame_centroid,
    values,
) -> xr.Dataset:
    """The run's scores and per-frame values, labelled (the integrated images' scores
    (criterion, fraction, detector), the long exposures' (recentring, detector))."""
    external = {c.name: c for c in criteria_external}
    criterion_units = ["1", "arcsec"] + [external[name].units for name, _ in criteria[2:]]
    photons = [np.nan if d.photons_per_frame is None else d.photons_per_frame for d in detectors]
    coords = {
        "criterion": ("criterion", [name for name, _ in criteria], _attrs("1", "frame selection criterion")),
        "larger_is_better": (
            "criterion",
            np.array([int(lb) for _, lb in criteria], np.int8),
            {
                **_attrs("1", "criterion ranks larger values first"),
                "flag_values": np.array([0, 1], np.int8),
                "flag_meanings": "smaller_is_better larger_is_better",
            },
        ),
        "criterion_units": ("criterion", criterion_units, _attrs("1", "units of the criterion")),
        "fraction": ("fraction", np.asarray(fractions, dtype=np.float64), _attrs("1", "fraction of frames selected")),
        "n_frames_selected": ("fraction", counts, _attrs("1", "number of frames selected")),
        "detector": ("detector", [d.name for d in detectors], _attrs("1", "detector model")),
        "photons_per_frame": (
            "detector",
            np.array(photons, np.float64),
            _attrs("1", "detected photons per frame (a count; NaN: noiseless)"),
        ),
        "read_noise_e": (
            "detector",
            np.array([d.read_noise_e for d in detectors], np.float64),
            _attrs("1", "read noise rms per pixel in electrons (EMCCD: referred to the input)"),
        ),
        "electron_multiplying": (
            "detector",
            np.array([d.electron_multiplying for d in detectors], np.int8),
            _attrs("1", "EMCCD gain register (Gamma-distributed gain, excess-noise factor sqrt 2)"),
        ),
        "photon_counting_threshold_e": (
            "detector",
            np.array(
                [np.nan if d.photon_counting_threshold_e is None else d.photon_counting_threshold_e for d in detectors],
                np.float64,
            ),
            _attrs("1", "photon-counting threshold in electrons (NaN: none)"),
        ),
        "recentring": (
            "recentring",
            ["none", "cog"],
            _attrs("1", "recentring of the long exposure: none or centre of gravity"),
        ),
        "frame": ("frame", np.arange(n_frames), _attrs("1", "frame index")),
        "axis": ("axis", ["y", "x"], _attrs("1", "image axis")),
    }
    sel = ("criterion", "fraction", "detector")
    data = {
        "strehl": (sel, s_int, _attrs("1", f"Strehl ratio of the integrated image {MEASURED}")),
        "fwhm_arcsec": (sel, fwhm_int, _attrs("arcsec", f"FWHM of the integrated image {MEASURED}")),
        "d50_arcsec": (
            sel,
            d50_int,
            _attrs("arcsec", f"diameter enclosing 50% of the energy of the integrated image {MEASURED}"),
        ),
        "long_exposure_strehl": (
            ("recentring", "detector"),
            s_long,
            _attrs("1", f"Strehl ratio of the long exposure {MEASURED}"),
        ),
        "long_exposure_fwhm_arcsec": (
            ("recentring", "detector"),
            fwhm_long,
            _attrs("arcsec", "FWHM of the long exposure"),
        ),
        "long_exposure_d50_arcsec": (
            ("recentring", "detector"),
            d50_long,
            _attrs("arcsec", "diameter enclosing 50% of the energy of the long exposure"),
        ),
        "frame_strehl": (
            ("detector", "frame"),
            frame_strehl,
            _attrs("1", f"Strehl ratio of the detected frame {MEASURED}"),
        ),
        "frame_d50_arcsec": (
            ("detector", "frame"),
            frame_d50_arcsec,
            _attrs("arcsec", "diameter enclosing 50% of the energy of the detected frame"),
        ),
        "frame_centroid_px": (
            ("detector", "frame", "axis"),
            frame_centroid,
            _attrs("1", "centre of gravity of the detected frame (pixel index)"),
        ),
        "frame_criterion": (
            ("criterion", "detector", "frame"),
            values,
            _attrs("1", "per-frame criterion value (units: criterion_units)"),
        ),
    }
    return xr.Dataset(data, coords=coords)


def add_noiseless_scores(ds: xr.Dataset, s_nl, fwhm_nl, d50_nl) -> None:
    """The scores of the same selection and shifts applied to the noiseless frames."""
    same = (
        "of the integrated image of the same selection and shifts applied to the noiseless frames (the "
        "simulation's yardstick: no pipeline has them)"
    )
    sel = ("criterion", "fraction", "detector")
    ds["strehl_noiseless"] = (sel, s_nl, _attrs("1", f"Strehl ratio {same}"))
    ds["fwhm_arcsec_noiseless"] = (sel, fwhm_nl, _attrs("arcsec", f"FWHM {same}"))
    ds["d50_arcsec_noiseless"] = (sel, d50_nl, _attrs("arcsec", f"diameter enclosing 50% of the energy {same}"))


def add_block_scores(ds: xr.Dataset, blocks: TimeBlocks) -> None:
    """Each time block's scores and the Monte-Carlo errors from them (batch means), if any blocks."""
    if not blocks.n_blocks:
        return
    sel = ("criterion", "fraction", "detector")
    block_dims = ("block", "criterion", "fraction", "detector")
    for metric, values_b in zip(("strehl", "fwhm_arcsec", "d50_arcsec"), blocks.values):
        ds[f"{metric}_block"] = (
            block_dims,
            values_b,
            _attrs(
                ds[metric].attrs["units"],
                f"{ds[metric].attrs['long_name']}, each time block selected on its own ({blocks.block_frames} frames)",
            ),
        )
        ds[f"{metric}_error"] = (
            sel,
            block_error(values_b),
            _attrs(
                ds[metric].attrs["units"],
                f"Monte-Carlo standard error of {metric}, from {blocks.n_blocks} time blocks (batch means)",
            ),
        )


def add_recentred_strehl(ds: xr.Dataset, frame_recentred_strehl: np.ndarray) -> None:
    ds["frame_recentred_strehl"] = (
        ("detector", "frame"),
        frame_recentred_strehl,
        _attrs(
            "1",
            "recentred frame's value at the recentred long exposure's peak pixel (within 3 pixels of the axis) "
            "over its flux and the diffraction-limited peak (their mean is that long exposure's Strehl)",
        ),
    )


def add_registration(ds: xr.Dataset, name: str, registered_px: np.ndarray, unregistered: np.ndarray) -> None:
    """The registration's per-frame positions (detector, frame, axis) and count of frames not registered."""
    ds["frame_registered_px"] = (
        ("detector", "frame", "axis"),
        registered_px,
        _attrs(
            "1",
            f"position of the frame's image by registration {name} (pixel index; NaN: not registered, not shifted)",
        ),
    )
    ds["unregistered_frames"] = (
        ("detector",),
        np.asarray(unregistered, np.int64),
        _attrs("1", f"frames registration {name} could not register (no flux or no peak): not shifted, NaN position"),
    )


def _over_flux(images: np.ndarray, crop_px: int, flux: np.ndarray | None) -> np.ndarray:
    """The central ``crop_px`` square of images (..., n, n) over their whole frame's flux (...)
    (default: their sums; elementwise, as cropping after dividing)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        total = images.sum(axis=(-2, -1), keepdims=True) if flux is None else np.asarray(flux)[..., None, None]
        return crop(images, crop_px) / total


def add_images(
    ds: xr.Dataset,
    images: np.ndarray,
    long_images,
    image_crop_px: int | None,
    flux: np.ndarray | None = None,
    long_flux=None,
) -> xr.Dataset:
    """``ds`` with the central ``image_crop_px`` square (None: whole) of the integrated images
    (criterion, fraction, detector, n, n) and the long exposures (recentring, detector, n, n) (or a
    sequence of (detector, n_r, n_r) per recentring), each over its whole frame's flux ``flux``
    (criterion, fraction, detector) and ``long_flux`` (a sequence of (detector,) or None per
    recentring; default: the images' sums) (float32): a crop sums to the fraction of the flux it
    holds. The crop is at most the smallest image given (a sub-pixel method's crop,
    :mod:`.cropped`)."""
    long_flux = [None] * len(long_images) if long_flux is None else long_flux
    size = min([images.shape[-1]] + [image.shape[-1] for image in long_images])
    m = size if image_crop_px is None else min(image_crop_px, size)
    unit = _over_flux(images, m, flux)
    unit_long = np.stack([_over_flux(image, m, f) for image, f in zip(long_images, long_flux)])
    offsets = np.arange(m) - m // 2
    ds = ds.assign_coords(
        y=("y", offsets, _attrs("1", "row offset from the optical axis pixel (n/2), in pixels")),
        x=("x", offsets, _attrs("1", "column offset from the optical axis pixel (n/2), in pixels")),
    )
    n = long_images[0].shape[-1]  # the long exposure without recentring: always the whole frame
    held = f"the central {m} x {m} pixels of the whole frame" if m < n else "the whole frame"
    ds["image"] = (
        ("criterion", "fraction", "detector", "y", "x"),
        unit.astype(np.float32),
        _attrs(
            "1",
            f"integrated image over the whole frame's flux: {held} (their sum is the fraction of the flux they hold)",
        ),
    )
    ds["long_exposure_image"] = (
        ("recentring", "detector", "y", "x"),
        unit_long.astype(np.float32),
        _attrs("1", f"long exposure (all frames) over the whole frame's flux: {held}"),
    )
    return ds
