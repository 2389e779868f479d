"""Flags of values no image can have, beside a lucky dataset's scores (:func:`add_limit_flags`):
a Strehl ratio above 1 or a FWHM or d50 below the diffraction-limited image's
(``<name>_beyond_diffraction_limit``), and a d50 set by the camera's field, a lower bound
(``<name>_field_bound``). int8 with CF ``flag_values``/``flag_meanings``, as
``<metric>_noise_dominated`` (:mod:`.dataset`)."""

import numpy as np
import xarray as xr


def _attrs(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


FIELD_EDGE = 0.4
"""A d50 above this fraction of the camera's field (its width) is the field's, not the image's:
a seeing-like image (a Moffat profile of beta 2.5, 90 % of its light within 2.5 times its
50 % radius) would then hold less than 90 % of its light within the field's inscribed disc, and
the light beyond the field is what a finite detector misses (the simulated field is periodic:
there it folds back in). The measured d50 is then a lower bound of the image's."""

LIMITED_METRICS = {"strehl": "Strehl ratio above 1", "fwhm_arcsec": "FWHM", "d50_arcsec": "d50"}
"""The metrics flagged ``<metric>_beyond_diffraction_limit`` (:func:`add_limit_flags`) and how
the limit is named: a Strehl ratio above 1, a FWHM or d50 below the diffraction-limited image's."""


def field_bound(d50, error, field_arcsec: float):
    """Where a d50 [arcsec] is a bound set by the field of ``field_arcsec`` across, not a measure
    of the image: NaN (its encircled energy never reaches 50 % within the field's inscribed
    disc), above :data:`FIELD_EDGE` of the field, or its Monte-Carlo ``error`` NaN (a time block's
    d50 so; None: no blocks)."""
    bound = ~(np.asarray(d50) <= FIELD_EDGE * field_arcsec)
    return bound if error is None else bound | np.isnan(error)


def field_bound_attrs(name: str, field_arcsec: float) -> dict:
    """The CF attributes of ``<d50 variable>_field_bound``."""
    return {
        **_attrs(
            "1",
            f"1 where {name} is a bound set by the camera's {field_arcsec:.3g}\" field, not a measure of the "
            "image: its encircled energy (or a time block's: the error NaN) does not reach 50 % within the "
            f"field's inscribed disc, or it exceeds {FIELD_EDGE:.0%} of the field (where a seeing-like image "
            "loses over 10 % of its light beyond the field): the image's d50 is at least the value given",
        ),
        "flag_values": np.array([0, 1], np.int8),
        "flag_meanings": "measured field_bound",
    }


LIMIT_ROUNDING = 1e-6
"""The relative margin of :func:`beyond_diffraction_limit`: the frames are float32, so the
diffraction-limited image's own Strehl is 1 to a few 1e-8 (1 + 3e-8 for the study's camera)."""


def beyond_diffraction_limit(metric: str, values, reference: float | None):
    """Where ``values`` of ``metric`` are beyond what any image can have: a Strehl ratio above 1,
    a FWHM or d50 [arcsec] below ``reference``, the diffraction-limited image's, by more than
    :data:`LIMIT_ROUNDING` (NaN: not flagged)."""
    values = np.asarray(values)
    with np.errstate(invalid="ignore"):
        if metric == "strehl":
            return values > 1.0 + LIMIT_ROUNDING
        return values < reference * (1 - LIMIT_ROUNDING)


def limit_flag_attrs(metric: str, name: str, reference: float | None) -> dict:
    """The CF attributes of ``<name>_beyond_diffraction_limit`` (``name`` a variable of ``metric``)."""
    limit = (
        "above 1"
        if metric == "strehl"
        else f"below the diffraction-limited image's ({reference:.3g}\", the same measure)"
    )
    return {
        **_attrs(
            "1",
            f"1 where {name} is {limit}: beyond any image, the detector noise piled up by the selection or "
            "the registration (the brightest noise stacked on the axis), not a measure of the image",
        ),
        "flag_values": np.array([0, 1], np.int8),
        "flag_meanings": "within_limit beyond_diffraction_limit",
    }


def add_limit_flags(ds: xr.Dataset) -> None:
    """Flags beside a lucky dataset's integrated and long-exposure scores (int8, CF flag
    attributes): ``<name>_beyond_diffraction_limit`` (:func:`beyond_diffraction_limit`) for the
    Strehl, FWHM and d50 of the integrated images (shift-and-add's, Fourier lucky imaging's
    ``fourier_*`` and the several stars' ``stars_*``) and the long exposures, against the dataset's
    ``diffraction_limited_fwhm_arcsec`` and ``diffraction_limited_d50_arcsec`` attributes; and
    ``<name>_field_bound`` (:func:`field_bound`) for ``d50_arcsec`` (with its error),
    ``d50_arcsec_noiseless``, ``long_exposure_d50_arcsec`` and ``stars_d50_arcsec`` (with its
    error), the field ``n_pixels`` x
    ``pixel_scale_arcsec`` across."""
    for metric in LIMITED_METRICS:
        reference = ds.attrs.get(f"diffraction_limited_{metric}")
        if metric != "strehl" and reference is None:
            continue
        for name in (metric, f"long_exposure_{metric}", f"fourier_{metric}", f"stars_{metric}"):
            if name in ds:
                flags = xr.DataArray(beyond_diffraction_limit(metric, ds[name].values, reference), dims=ds[name].dims)
                ds[f"{name}_beyond_diffraction_limit"] = flags.astype(np.int8).assign_attrs(
                    limit_flag_attrs(metric, name, reference)
                )
    if "n_pixels" not in ds.attrs:
        return
    field = float(ds.attrs["n_pixels"]) * float(ds.attrs["pixel_scale_arcsec"])
    for name, error in (
        ("d50_arcsec", "d50_arcsec_error"),
        ("d50_arcsec_noiseless", None),
        ("long_exposure_d50_arcsec", None),
        ("stars_d50_arcsec", "stars_d50_arcsec_error"),
    ):
        if name in ds:
            err = ds[error].transpose(*ds[name].dims).values if error in ds else None
            flags = xr.DataArray(field_bound(ds[name].values, err, field), dims=ds[name].dims)
            ds[f"{name}_field_bound"] = flags.astype(np.int8).assign_attrs(field_bound_attrs(name, field))
