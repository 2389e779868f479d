"""FITS export of a case's images: every integrated (lucky) and long-exposure image of
``lucky.nc``, per target, registration method, criterion, fraction, recentring and detector,
with the header an astronomer's tools read: a linear WCS in arcsec from the optical axis
(astropy's WCS), ``BUNIT`` in FITS's unit syntax (astropy's units), ``DATE``, ``EXPTIME``
(the frames the image adds up times the frame time: the selected frames' for a lucky image,
all for a long exposure), the wavelength, the image's Strehl, FWHM and d50 with their
Monte-Carlo errors, where a noisy detector's metric is noise-dominated, and the provenance
(case, seed, config sha256, code version).

Two layouts: ``images`` (one 2-D image extension per image) and ``cube`` (for DS9's cube
dialog: per target, registration, criterion and detector one cube whose third axis is the
fraction of frames selected; the long exposures as images). Either way extension 1 is the
``INDEX`` table, one row per image (a cube: per plane) with its extension number, plane and
keywords, so an image is found by its values as well as by its name.

The pixels are those ``lucky.nc`` holds, bit for bit: each over the whole frame's flux (a
dimensionless ratio, ``BUNIT = ''``), so an image of the whole frame sums to 1 and a crop to
the fraction of the flux it holds (``FLUXFRAC``); ``lucky.image_crop_px: null`` keeps whole
frames.
"""

import datetime
import json
import os
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..lucky.dataset import NOISE_DOMINATED, noise_dominated
from .datasets import open_dataset, require_finite_lucky
from .kinds import require_kind

LAYOUTS = ("images", "cube")
"""``images``: a 2-D extension per image; ``cube``: the fractions of a lucky image as a cube's third axis."""

QUALITY = (("STREHL", "strehl", "Strehl ratio"), ("FWHM", "fwhm_arcsec", "[arcsec] FWHM"))
QUALITY += (("D50", "d50_arcsec", "[arcsec] 50%-energy diameter"),)
"""(keyword, lucky.nc metric, comment) of an image's quality cards."""

INDEX_COLUMNS = (
    ("HDU", "J", "extension number of the image"),
    ("EXTNAME", "A", "its name"),
    ("PLANE", "J", "plane of a cube (1-based; 1 for a 2-D image)"),
    ("IMAGETYP", "A", "lucky or long exposure"),
    ("TARGET", "J", "target index"),
    ("REGISTR", "A", "registration method ('' for a long exposure not recentred)"),
    ("CRITERIO", "A", "frame selection criterion ('' for a long exposure)"),
    ("FRACTION", "D", "fraction of frames selected (NaN for a long exposure)"),
    ("RECENTR", "A", "recentring of a long exposure: none or the registration method"),
    ("DETECTOR", "A", "detector model"),
    ("PHOTONS", "D", "detected photons per frame (NaN: noiseless)"),
    ("RDNOISE", "D", "read noise rms per pixel [electron]"),
    ("EXPTIME", "D", "[s] exposure time of the frames the image adds up"),
    ("STREHL", "D", "Strehl ratio (NaN: undefined)"),
    ("FWHM", "D", "[arcsec] FWHM (NaN: undefined)"),
    ("D50", "D", "[arcsec] 50%-energy diameter (NaN: undefined)"),
    ("STREHLND", "I", "1: Strehl noise-dominated, 0: not, -1: no noiseless counterpart"),
    ("FWHMND", "I", "1: FWHM noise-dominated, 0: not, -1: no noiseless counterpart"),
    ("D50ND", "I", "1: d50 noise-dominated, 0: not, -1: no noiseless counterpart"),
)
"""The ``INDEX`` table's columns: (name, FITS format, description)."""

PLANE_KEYS = {
    "NCOMBINE": "NCOMB",
    "EXPTIME": "EXPT",
    "STREHL": "STR",
    "STREHLE": "STRE",
    "FWHM": "FWHM",
    "FWHME": "FWHME",
    "D50": "D50",
    "D50E": "D50E",
    "STREHLND": "STRND",
    "FWHMND": "FWHMND",
    "D50ND": "D50ND",
}
"""A cube's per-plane keywords: ``<short><k>`` for plane k (at most 8 characters up to plane 99)."""


def _date() -> str:
    """FITS's ``DATE``: when the file was written, UTC."""
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")


def _provenance_cards(lucky: xr.Dataset) -> list[tuple]:
    config = json.loads(lucky.attrs["config_json"])
    return [
        ("ORIGIN", "luckyao", "Monte-Carlo LGS-assisted lucky imaging"),
        ("DATE", _date(), "UTC date the file was written"),
        ("CASE", str(lucky.attrs.get("case", "")), "study case"),
        ("SEED", int(lucky.attrs["seed"]), "master seed of the study"),
        ("CFGHASH", str(lucky.attrs["config_sha256"]), "sha256 of the case's resolved config"),
        ("CODEVER", str(lucky.attrs["code_version"])[:68], "luckyao version and git commit"),
        ("WAVELENG", float(config["camera"]["wavelength_m"]), "[m] science wavelength"),
        ("TELDIAM", float(config["telescope"]["diameter_m"]), "[m] telescope diameter"),
        ("FRAMETIM", _frame_time_s(lucky), "[s] lucky frame exposure"),
        ("NFRAMES", int(lucky.sizes["frame"]), "lucky frames of the case"),
        ("FRAMEPIX", int(lucky.attrs["n_pixels"]), "pixels across the whole frame"),
    ]


def _frame_time_s(lucky: xr.Dataset) -> float:
    return float(json.loads(lucky.attrs["config_json"])["camera"]["frame_time_s"])


def _wcs_cards(lucky: xr.Dataset, fractions=None) -> list[tuple]:
    """A linear WCS (astropy's): offsets from the optical axis (the pixel whose offset
    coordinate is 0) in arcsec; with ``fractions``, a third axis: the plane's index, its
    fraction in ``FRAC<k>``."""
    import astropy.units as u
    from astropy.wcs import WCS

    scale = float(lucky.attrs["pixel_scale_arcsec"])
    wcs = WCS(naxis=2 if fractions is None else 3)
    axis_pixels = [float(np.flatnonzero(lucky[name].values == 0)[0]) + 1 for name in ("x", "y")]
    wcs.wcs.ctype = ["XOFFSET", "YOFFSET"] + ([] if fractions is None else ["FRACIDX"])
    wcs.wcs.cunit = [u.arcsec, u.arcsec] + ([] if fractions is None else [""])
    wcs.wcs.crpix = axis_pixels + ([] if fractions is None else [1.0])
    wcs.wcs.cdelt = [scale, scale] + ([] if fractions is None else [1.0])
    wcs.wcs.crval = [0.0, 0.0] + ([] if fractions is None else [1.0])
    header = wcs.to_header()
    for irrelevant in ("LATPOLE", "MJDREF"):  # no celestial axes, no time axis
        header.remove(irrelevant, ignore_missing=True)
    cards = [(card.keyword, card.value, card.comment) for card in header.cards]
    cards.append(("PIXSCALE", scale, "[arcsec/pixel]"))
    if fractions is not None:
        cards += [
            (f"FRAC{k}", float(f), f"fraction of frames selected in plane {k}") for k, f in enumerate(fractions, 1)
        ]
    return cards


def _quality_values(values: xr.Dataset, prefix: str = "") -> dict:
    """Keyword -> (value, comment) of an image's Strehl, FWHM, d50 (and their errors when known)."""
    cards = {}
    for key, name, comment in QUALITY:
        if f"{prefix}{name}" in values:
            cards[key] = (float(values[f"{prefix}{name}"]), comment)
        if f"{prefix}{name}_error" in values:
            cards[f"{key}E"] = (float(values[f"{prefix}{name}_error"]), f"Monte-Carlo standard error of {key}")
    return cards


def _noise_flags(values: xr.Dataset) -> dict:
    """Keyword -> (whether noise-dominated, comment) of each metric with its value on the
    noiseless frames (``lucky.nc``'s ``<metric>_noise_dominated``, from the same function)."""
    return {
        f"{key}ND": (
            bool(noise_dominated(np.float64(values[name]), np.float64(values[f"{name}_noiseless"]))),
            f"T: {key} noise-dominated (>{NOISE_DOMINATED:.0%} off noiseless)",
        )
        for key, name, _ in QUALITY
        if f"{name}_noiseless" in values
    }


@dataclass
class _Image:
    """One image (or a cube of them) to write: its pixels, name, header cards and index rows."""

    data: np.ndarray
    name: str
    cards: list[tuple]
    rows: list[dict]


def _detector_cards(det: xr.Dataset, detector: str) -> list[tuple]:
    photons = float(det.photons_per_frame)
    noiseless = not np.isfinite(photons)
    return (
        [("DETECTOR", str(detector), "detector model"), ("NOISELES", noiseless, "T: noiseless detector")]
        + ([] if noiseless else [("PHOTONS", photons, "detected photons per frame")])
        + [("RDNOISE", float(det.read_noise_e), "[e-] read noise rms per pixel")]
    )


def _row(cards: list[tuple], quality: dict, flags: dict) -> dict:
    """An ``INDEX`` row from an image's cards, quality and noise flags (-1: not known)."""
    values = {key: value for key, value, _ in cards}
    row = {name: values.get(name, "" if form == "A" else np.nan) for name, form, _ in INDEX_COLUMNS}
    row["PLANE"] = 1
    row.update({key: quality[key][0] if key in quality else np.nan for key, _, _ in QUALITY})
    row.update({f"{key}ND": int(flags[f"{key}ND"][0]) if f"{key}ND" in flags else -1 for key, _, _ in QUALITY})
    row["PHOTONS"] = values.get("PHOTONS", np.nan)
    return row


def _cards(values: dict) -> list[tuple]:
    return [(key, value, comment) for key, (value, comment) in values.items()]


def _images(lucky: xr.Dataset, detectors, registrations, layout: str):
    """The :class:`_Image` of every image of the lucky dataset (with a ``registration``
    dimension): per target and detector, the lucky images of each registration method
    (images, or a cube along the fraction), then the long exposure, then the one recentred by
    each method."""
    frame_time = _frame_time_s(lucky)
    n_frames = int(lucky.sizes["frame"])
    common = _provenance_cards(lucky)
    plane_wcs, cube_wcs = _wcs_cards(lucky), _wcs_cards(lucky, lucky.fraction.values)
    for t in range(lucky.sizes["target"]):
        target = lucky.isel(target=t)
        where = [
            ("TARGET", t, "target index"),
            ("TARGETX", float(target.target_x_arcsec), "[arcsec] target direction x"),
            ("TARGETY", float(target.target_y_arcsec), "[arcsec] target direction y"),
        ]
        for detector in detectors:
            det = target.sel(detector=detector)
            noise = _detector_cards(det, detector)
            for method in registrations:
                for criterion in lucky.criterion.values:
                    yield from _lucky_images(
                        det.sel(registration=method, criterion=criterion),
                        (t, method, criterion, detector),
                        common + where + noise,
                        (plane_wcs, cube_wcs),
                        frame_time,
                        layout,
                    )
            for recentring, method in [("none", registrations[0])] + [("cog", m) for m in registrations]:
                cell = det.sel(registration=method, recentring=recentring)
                shown = "none" if recentring == "none" else str(method)
                cards = [
                    ("IMAGETYP", "long exposure", "all frames"),
                    ("RECENTR", shown, "none, or each frame recentred by REGISTR"),
                    *([] if recentring == "none" else [("REGISTR", str(method), "registration method of the frames")]),
                    ("NCOMBINE", n_frames, "frames added up"),
                    ("EXPTIME", n_frames * frame_time, "[s] the frames' total exposure"),
                ]
                quality = _quality_values(cell, "long_exposure_")
                error = "long_exposure_strehl_error" if recentring == "none" else "recentred_long_exposure_strehl_error"
                if error in cell:
                    quality["STREHLE"] = (float(cell[error]), "Monte-Carlo standard error")
                header = common + where + noise + cards + _cards(quality)
                yield _Image(
                    cell.long_exposure_image.values,
                    f"LONG_T{t}_{shown}_{detector}".upper(),
                    plane_wcs + header,
                    [_row(header, quality, {})],
                )


def _lucky_images(cell: xr.Dataset, key: tuple, header: list[tuple], wcs: tuple, frame_time: float, layout: str):
    """The lucky images of one (target, registration, criterion, detector) ``cell``: one per
    fraction, or one cube (``layout``)."""
    t, method, criterion, detector = key
    kind = [
        ("IMAGETYP", "lucky", "shift-and-add of the selected frames"),
        ("REGISTR", str(method), "registration method of the frames"),
        ("CRITERIO", str(criterion), "frame selection criterion"),
    ]
    planes = []
    for fraction in cell.fraction.values:
        plane = cell.sel(fraction=fraction)
        n_selected = int(plane.n_frames_selected)
        cards = [
            ("FRACTION", float(fraction), "fraction of frames selected"),
            ("NCOMBINE", n_selected, "frames added up"),
            ("EXPTIME", n_selected * frame_time, "[s] the selected frames' total exposure"),
        ]
        planes.append((plane, cards, _quality_values(plane), _noise_flags(plane)))
    if layout == "images":
        for plane, cards, quality, flags in planes:
            fraction = float(plane.fraction)
            cards = header + kind + cards + _cards(quality) + _cards(flags)
            name = f"LUCKY_T{t}_{method}_{criterion}_{fraction:g}_{detector}".upper()
            yield _Image(plane.image.values, name, wcs[0] + cards, [_row(cards, quality, flags)])
        return
    per_plane = []
    rows = []
    for k, (plane, cards, quality, flags) in enumerate(planes, 1):
        for key, value, comment in cards[1:] + _cards(quality) + _cards(flags):  # FRAC<k>: the WCS's
            per_plane.append((f"{PLANE_KEYS[key]}{k}", value, f"plane {k}: {comment}"))
        rows.append({**_row(header + kind + cards, quality, flags), "PLANE": k})
    cube = cell.image.transpose("fraction", "y", "x").values
    name = f"LUCKY_T{t}_{method}_{criterion}_{detector}".upper()
    yield _Image(cube, name, wcs[1] + header + kind + per_plane, rows)


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
    """An image extension: the pixels as float32 (as ``lucky.nc`` holds them), the cards, the
    unit (dimensionless, in FITS's syntax) and the flux the image holds (a cube: per plane)."""
    import astropy.units as u

    hdu = fits.ImageHDU(np.asarray(image, dtype=np.float32))
    hdu.header["EXTNAME"] = (name, _fitting(name, "extension name"))  # a long name: without comment
    for key, value, comment in cards:
        _set_card(hdu.header, key, value, comment)
    hdu.header["BUNIT"] = (u.dimensionless_unscaled.to_string("fits"), "over the whole frame's flux")
    flux = np.sum(image, axis=(-2, -1), dtype=np.float64)
    if np.ndim(flux) == 0:
        _set_card(hdu.header, "FLUXFRAC", float(flux), "the frame's flux in this image")
    else:
        for k, value in enumerate(flux, 1):
            _set_card(hdu.header, f"FLUXFR{k}", float(value), f"the frame's flux in plane {k}")
    return hdu


def _index_hdu(fits, rows: list[dict]):
    """The ``INDEX`` table: a row per image or cube plane (:data:`INDEX_COLUMNS`)."""
    columns = []
    for name, form, description in INDEX_COLUMNS:
        values = [row[name] for row in rows]
        if form == "A":
            form = f"{max(1, max((len(v) for v in values), default=1))}A"
        columns.append(fits.Column(name=name, format=form, array=np.array(values)))
    hdu = fits.BinTableHDU.from_columns(columns, name="INDEX")
    for k, (_, _, description) in enumerate(INDEX_COLUMNS, 1):
        hdu.header[f"TCOMM{k}"] = description
    return hdu


def export_fits(lucky_path, out_path, detectors=None, registrations=None, layout: str = "images") -> int:
    """Write ``lucky_path``'s images as one FITS file: a primary header with the case's
    provenance, the ``INDEX`` table, then an extension per image (``layout`` ``images``) or per
    cube of fractions (``cube``), of the named ``detectors`` and ``registrations`` (default:
    all); returns the number of images (a cube's planes each one)."""
    from astropy.io import fits

    if layout not in LAYOUTS:
        raise ValueError(f"FITS layout {layout!r}: one of {', '.join(LAYOUTS)}")
    lucky = open_dataset(lucky_path, "lucky")
    require_kind(lucky, "luckyao lucky imaging of case ", f"export of '{lucky_path}'")
    require_finite_lucky(lucky, f"lucky file '{lucky_path}'")  # the rule it is written with, checked again
    if "image" not in lucky:
        raise ValueError(f"'{lucky_path}' holds no images (its lucky.image_crop_px was 0)")
    if "registration" not in lucky.dims:  # a dataset of one method, as run_lucky writes it
        lucky = lucky.expand_dims(registration=["cog"])
    detectors = _chosen(detectors, lucky.detector.values, "detectors")
    registrations = _chosen(registrations, lucky.registration.values, "registration methods")
    images = list(_images(lucky, detectors, registrations, layout))
    rows = [{**row, "HDU": k, "EXTNAME": image.name} for k, image in enumerate(images, 2) for row in image.rows]
    primary = fits.PrimaryHDU()
    for key, value, comment in _provenance_cards(lucky):
        _set_card(primary.header, key, value, comment)
    primary.header["LAYOUT"] = (layout, "images: 2-D per image; cube: fraction as axis 3")
    primary.header["NIMAGES"] = (len(rows), "images (a cube's planes each one)")
    primary.header["INDEXHDU"] = (1, "extension of the INDEX table of the images")
    partial = f"{out_path}.partial"
    fits.HDUList([primary, _index_hdu(fits, rows)]).writeto(partial, overwrite=True)
    for image in images:  # appended one at a time: one header in memory (thousands per noise case)
        hdu = _hdu(fits, image.data, image.name, image.cards)
        with fits.StreamingHDU(partial, hdu.header) as stream:
            stream.write(hdu.data)
    os.replace(partial, out_path)
    return len(rows)


def _chosen(names, available, what: str) -> list[str]:
    """``names`` (default: all ``available``), each one of ``available``."""
    available = [str(a) for a in available]
    names = available if names is None else [str(n) for n in names]
    unknown = [n for n in names if n not in available]
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; the case has {', '.join(available)}")
    return names
