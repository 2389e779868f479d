"""FITS export of a case's images: every integrated (lucky) and long-exposure image of
``lucky.nc`` (of the baseline registration, ``cog``), per target, criterion, fraction, recentring
and detector, one image extension each, with the header an astronomer's tools read: a linear WCS in arcsec
from the optical axis, the wavelength, the image's Strehl, FWHM and d50 with their
Monte-Carlo errors, and the provenance (case, seed, config sha256, code version).

The pixels are those ``lucky.nc`` holds: each over the whole frame's flux, so an
image of the whole frame sums to 1 and a crop to the fraction of the flux it holds
(``FLUXFRAC``); ``lucky.image_crop_px: null`` keeps whole frames.
"""

import json
import os

import numpy as np
import xarray as xr

from .datasets import open_dataset, require_finite_lucky
from .kinds import require_kind


def _provenance_cards(lucky: xr.Dataset) -> list[tuple]:
    config = json.loads(lucky.attrs["config_json"])
    return [
        ("ORIGIN", "luckyao", "Monte-Carlo LGS-assisted lucky imaging"),
        ("CASE", str(lucky.attrs.get("case", "")), "study case"),
        ("SEED", int(lucky.attrs["seed"]), "master seed of the study"),
        ("CFGHASH", str(lucky.attrs["config_sha256"]), "sha256 of the case's resolved config"),
        ("CODEVER", str(lucky.attrs["code_version"])[:68], "luckyao version and git commit"),
        ("WAVELENG", float(config["camera"]["wavelength_m"]), "[m] science wavelength"),
        ("TELDIAM", float(config["telescope"]["diameter_m"]), "[m] telescope diameter"),
        ("FRAMETIM", float(config["camera"]["frame_time_s"]), "[s] lucky frame exposure"),
        ("NFRAMES", int(lucky.sizes["frame"]), "lucky frames of the case"),
        ("FRAMEPIX", int(lucky.attrs["n_pixels"]), "pixels across the whole frame"),
    ]


def _wcs_cards(lucky: xr.Dataset, pixel_scale_arcsec: float) -> list[tuple]:
    """Linear WCS: offsets from the optical axis (the pixel whose offset coordinate is 0)
    in arcsec."""
    cards = [("WCSAXES", 2, "")]
    for axis, name in ((1, "x"), (2, "y")):
        axis_pixel = int(np.flatnonzero(lucky[name].values == 0)[0]) + 1
        cards += [
            (f"CTYPE{axis}", f"{name.upper()}OFFSET", "offset from the optical axis"),
            (f"CUNIT{axis}", "arcsec", ""),
            (f"CRPIX{axis}", float(axis_pixel), "the optical axis pixel (1-based)"),
            (f"CRVAL{axis}", 0.0, ""),
            (f"CDELT{axis}", pixel_scale_arcsec, "[arcsec] pixel scale"),
        ]
    return cards + [("PIXSCALE", pixel_scale_arcsec, "[arcsec/pixel]")]


def _quality_cards(values: xr.Dataset, prefix: str = "") -> list[tuple]:
    """Strehl, FWHM, d50 of an image (and their errors when known), from ``values``."""
    names = (
        ("STREHL", "strehl", "Strehl ratio"),
        ("FWHM", "fwhm_arcsec", "[arcsec] FWHM"),
        ("D50", "d50_arcsec", "[arcsec] 50%-energy diameter"),
    )
    cards = []
    for key, name, comment in names:
        if f"{prefix}{name}" in values:
            cards.append((key, float(values[f"{prefix}{name}"]), comment))
        error = f"{prefix}{name}_error"
        if error in values:
            cards.append((f"{key}E", float(values[error]), f"Monte-Carlo standard error of {key}"))
    return cards


def image_hdus(lucky: xr.Dataset, detectors=None):
    """One ``astropy.io.fits.ImageHDU`` per image of a lucky dataset (optionally only of
    the named detectors): the lucky images, then the long exposures."""
    from astropy.io import fits

    if "image" not in lucky:
        raise ValueError("the lucky dataset holds no images (run_lucky's image_crop_px was 0)")
    detectors = list(lucky.detector.values) if detectors is None else list(detectors)
    unknown = set(detectors) - set(lucky.detector.values)
    if unknown:
        raise ValueError(f"unknown detectors {sorted(unknown)}; the case has {', '.join(lucky.detector.values)}")
    common = _provenance_cards(lucky) + _wcs_cards(lucky, float(lucky.attrs["pixel_scale_arcsec"]))
    for t in range(lucky.sizes["target"]):
        target = lucky.isel(target=t)
        where = [
            ("TARGET", t, "target index"),
            ("TARGETX", float(target.target_x_arcsec), "[arcsec] target direction x"),
            ("TARGETY", float(target.target_y_arcsec), "[arcsec] target direction y"),
        ]
        for detector in detectors:
            det = target.sel(detector=detector)
            photons = float(det.photons_per_frame)
            noise = [
                ("DETECTOR", str(detector), "detector model"),
                ("PHOTONS", photons if np.isfinite(photons) else "none", "detected photons per frame"),
                ("RDNOISE", float(det.read_noise_e), "[e-] read noise rms per pixel"),
            ]
            for criterion in lucky.criterion.values:
                for fraction in lucky.fraction.values:
                    cell = det.sel(criterion=criterion, fraction=fraction)
                    cards = [
                        ("IMAGETYP", "lucky", "shift-and-add of the selected frames"),
                        ("CRITERIO", str(criterion), "frame selection criterion"),
                        ("FRACTION", float(fraction), "fraction of frames selected"),
                    ]
                    name = f"LUCKY_T{t}_{criterion}_{fraction:g}_{detector}".upper()
                    yield _hdu(fits, cell.image.values, name, common + where + noise + cards + _quality_cards(cell))
            for recentring in lucky.recentring.values:
                cell = det.sel(recentring=recentring)
                cards = [
                    ("IMAGETYP", "long exposure", "all frames"),
                    ("RECENTR", str(recentring), "none, or cog: each frame recentred on its centroid"),
                ]
                quality = _quality_cards(cell, "long_exposure_")
                if recentring == "none" and "long_exposure_strehl_error" in cell:
                    quality.append(("STREHLE", float(cell.long_exposure_strehl_error), "Monte-Carlo standard error"))
                elif "recentred_long_exposure_strehl_error" in cell:
                    quality.append(
                        ("STREHLE", float(cell.recentred_long_exposure_strehl_error), "Monte-Carlo standard error")
                    )
                name = f"LONG_T{t}_{recentring}_{detector}".upper()
                yield _hdu(fits, cell.long_exposure_image.values, name, common + where + noise + cards + quality)


def _fitting(value, comment: str) -> str:
    """The comment, or none when it would not fit on the value's 80-character card."""
    return comment if max(20, len(str(value)) + 2) + len(comment) <= 66 else ""


def _set_card(header, key: str, value, comment: str) -> None:
    """A header card; a NaN or infinite value (a noise-dominated image's metric) is written
    as FITS's undefined value, which FITS has instead of NaN, and said so in the comment."""
    if isinstance(value, float) and not np.isfinite(value):
        value, comment = None, f"undefined ({value}): {comment}"
    header[key] = (value, _fitting(value, comment))


def _hdu(fits, image: np.ndarray, name: str, cards: list[tuple]):
    hdu = fits.ImageHDU(np.asarray(image, dtype=np.float32), name=name)
    for key, value, comment in cards:
        _set_card(hdu.header, key, value, comment)
    hdu.header["BUNIT"] = ("1", "pixel over the whole frame's flux")
    _set_card(hdu.header, "FLUXFRAC", float(np.sum(image, dtype=np.float64)), "the frame's flux in this image")
    return hdu


def export_fits(lucky_path, out_path, detectors=None) -> int:
    """Write ``lucky_path``'s images as one FITS file (a primary header with the case's
    provenance, then an image extension per image); returns the number of images."""
    from astropy.io import fits

    lucky = open_dataset(lucky_path, "lucky")
    require_kind(lucky, "luckyao lucky imaging of case ", f"export of '{lucky_path}'")
    require_finite_lucky(lucky, f"lucky file '{lucky_path}'")  # the rule it is written with, checked again
    if "registration" in lucky.dims:  # the baseline's images (cog)
        lucky = lucky.sel(registration="cog")
    primary = fits.PrimaryHDU()
    for key, value, comment in _provenance_cards(lucky):
        _set_card(primary.header, key, value, comment)
    hdus = list(image_hdus(lucky, detectors))
    primary.header["NIMAGES"] = (len(hdus), "image extensions that follow")
    partial = f"{out_path}.partial"
    fits.HDUList([primary, *hdus]).writeto(partial, overwrite=True)
    os.replace(partial, out_path)
    return len(hdus)
