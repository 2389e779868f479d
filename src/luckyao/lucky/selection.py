"""Lucky imaging post-processing of one target's frame cube: select, shift and add, score.

Method (Basden 2014, sec. "Shift and add"): every frame gets a scalar quality (image
Strehl, 50%-energy diameter d50, or an external per-frame value such as the LGS
tilt-removed wavefront rms); frames are ranked over the whole cube; for each fraction
``f`` the best ``n_f = max(1, round(f n))`` frames are recentred on their centre of
gravity by a whole number of pixels and added. The integrated images are scored by
Strehl, FWHM and d50 (:mod:`luckyao.lucky.metrics`).

Frames are ``(k, n, n)`` float32 unit-flux noiseless images indexed ``[y, x]`` with
the optical axis on pixel ``(n/2, n/2)``; detector noise (:mod:`luckyao.lucky.detector`)
is applied here, so one simulated cube serves every detector model.
"""

import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..progress import Progress
from .detector import Detector, apply_detector
from .metrics import EncircledEnergy, centroid_px, fwhm_arcsec, strehl

IMAGE_CRITERIA = (("strehl", True), ("d50", False))
"""Image criteria computed per frame: (name, larger_is_better)."""


@dataclass(frozen=True, eq=False)
class ExternalCriterion:
    """A per-frame selection criterion not computed from the image.

    ``values`` (n_frames,) in ``units``; ``larger_is_better`` orders them (e.g. the LGS
    tilt-removed wavefront rms [nm] has ``larger_is_better=False``). NaN ranks last.
    """

    name: str
    values: np.ndarray
    larger_is_better: bool
    units: str = "1"
    long_name: str = ""


def fraction_counts(n_frames: int, fractions: Sequence[float]) -> np.ndarray:
    """Frames kept per fraction, ``n_k = max(1, round(f_k n_frames))``, int64 (n_fractions,).

    ``round`` is numpy's round-half-to-even; fractions must lie in (0, 1].
    """
    fractions = np.asarray(fractions, dtype=np.float64)
    if np.any(~(fractions > 0)) or np.any(fractions > 1):
        raise ValueError(f"fractions must lie in (0, 1], got {fractions}")
    return np.maximum(1, np.rint(fractions * n_frames)).astype(np.int64)


def rank_frames(values: np.ndarray, larger_is_better: bool) -> np.ndarray:
    """Frame indices from best to worst, shape (n_frames,).

    Exact stable sort over all frames: ties keep frame-index order; NaN ranks last.
    """
    values = np.asarray(values, dtype=np.float64)
    key = -values if larger_is_better else values
    return np.argsort(key, kind="stable")


def selection_bins(order: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Assign frames to nested selection bins, for cumulative summation.

    ``order`` (n_frames,) frame indices best first (:func:`rank_frames`); ``counts``
    (n_fractions,) frames kept per fraction. With ``u`` the sorted distinct counts,
    the frame of rank ``r`` goes to bin ``b`` with ``u[b-1] <= r < u[b]`` (``u[-1]=0``),
    or -1 if ``r >= max(u)``. Returns ``(bin_of_frame (n_frames,), last_bin
    (n_fractions,))``: fraction ``k``'s selection is the union of bins ``0..last_bin[k]``.
    """
    distinct = np.unique(counts)
    bin_of_rank = np.searchsorted(distinct, np.arange(len(order)), side="right")
    bin_of_rank[bin_of_rank == len(distinct)] = -1
    bin_of_frame = np.empty(len(order), dtype=np.int64)
    bin_of_frame[order] = bin_of_rank
    return bin_of_frame, np.searchsorted(distinct, counts)


def recentring_shifts_px(centroids_px: np.ndarray, n_pixels: int) -> np.ndarray:
    """Whole-pixel shifts (..., 2) (y, x) that bring centroids (..., 2) nearest to (n/2, n/2).

    ``s = floor(n/2 - c + 1/2)`` (nearest integer, halves rounded up). Non-finite
    centroids (zero-flux frames) get no shift.
    """
    target = n_pixels // 2
    shifts = np.floor(target - np.asarray(centroids_px, dtype=np.float64) + 0.5)
    return np.where(np.isfinite(shifts), shifts, 0).astype(np.int64)


def shift_frames(frames: np.ndarray, shifts_px: np.ndarray) -> np.ndarray:
    """Frames (k, n, n) each rolled by its integer shift (k, 2) (y, x), new array.

    Circular shift with ``np.roll`` semantics, ``out[y, x] = in[(y - s_y) mod n,
    (x - s_x) mod n]``: consistent with the simulated field, which is periodic over
    the frame (a frame is the power spectrum of a sampled pupil). Vectorised gather.
    """
    frames = np.asarray(frames)
    k, ny, nx = frames.shape
    shifts_px = np.asarray(shifts_px, dtype=np.int64).reshape(k, 2)
    rows = (np.arange(ny)[None, :] - shifts_px[:, :1]) % ny  # (k, ny)
    cols = (np.arange(nx)[None, :] - shifts_px[:, 1:]) % nx  # (k, nx)
    out = np.take_along_axis(frames, rows[:, :, None], axis=1)
    return np.take_along_axis(out, cols[:, None, :], axis=2)


def shift_and_add(frames: np.ndarray) -> np.ndarray:
    """Sum (n, n) float64 of frames (k, n, n) recentred on their centre of gravity.

    Each frame is rolled by :func:`recentring_shifts_px` of its own
    :func:`luckyao.lucky.metrics.centroid_px` (:func:`shift_frames`), then all are added.
    """
    frames = np.asarray(frames)
    shifts = recentring_shifts_px(centroid_px(frames), frames.shape[-1])
    return shift_frames(frames, shifts).sum(axis=0, dtype=np.float64)


def detector_key(name: str) -> int:
    """Stable integer of a detector's name that keys its noise: ``zlib.crc32`` of its UTF-8.

    Not Python's ``hash`` (salted per process), so draws are reproducible across runs.
    """
    return zlib.crc32(name.encode("utf-8"))


def _noisy(frames: np.ndarray, detector: Detector, seed: int, start: int) -> np.ndarray:
    """Detector frames of one chunk; the rng is ``default_rng([seed, detector_key(name),
    start])``: the draws depend on the detector's name, not on the other detectors."""
    return apply_detector(frames, detector,
                          np.random.default_rng([seed, detector_key(detector.name), start]))


def _score(partial: np.ndarray, n: int, n_bins: int, last_bin: np.ndarray,
           encircled: EncircledEnergy, diffraction_limited_peak: float,
           pixel_scale_arcsec: float) -> tuple[np.ndarray, ...]:
    """Integrated images of the (det, criterion x bin, n x n) partial sums (cumulative sums
    of the bins of each fraction), as (criterion, fraction, det, n, n), and their Strehl,
    FWHM [arcsec] and d50 [arcsec] (criterion, fraction, det). One code path for the noisy
    and the noiseless sums, so equal sums give bit-identical scores."""
    n_det, rows, _ = partial.shape
    cumulative = np.cumsum(partial.reshape(n_det, rows // n_bins, n_bins, n, n), axis=2)
    images = cumulative[:, :, last_bin]  # (det, crit, fraction, n, n)
    del cumulative
    images = np.moveaxis(images, 0, 2)  # (crit, fraction, det, n, n)
    s_int = strehl(images, diffraction_limited_peak)
    d50_int = 2 * encircled.radius_px(images) * pixel_scale_arcsec
    fwhm_int = fwhm_arcsec(images, pixel_scale_arcsec)
    return images, s_int, fwhm_int, d50_int


def _chunks(iter_chunks: Callable[[], Iterable[tuple[int, np.ndarray]]],
            n_frames: int) -> Iterator[tuple[int, np.ndarray]]:
    """Validated chunks: contiguous, covering frames 0..n_frames-1, square float frames."""
    expected = 0
    for start, frames in iter_chunks():
        frames = np.asarray(frames)
        if start != expected or frames.ndim != 3 or frames.shape[1] != frames.shape[2]:
            raise ValueError(f"chunk at {start} (expected {expected}), shape {frames.shape}")
        expected += len(frames)
        yield start, frames
    if expected != n_frames:
        raise ValueError(f"chunks cover {expected} frames, expected {n_frames}")


def _crop(images: np.ndarray, crop_px: int | None) -> np.ndarray:
    """Central ``crop_px`` square around pixel (n/2, n/2) of images (..., n, n)."""
    n = images.shape[-1]
    if crop_px is None or crop_px >= n:
        return images
    lo = n // 2 - crop_px // 2
    return images[..., lo:lo + crop_px, lo:lo + crop_px]


def _attrs(units: str, long_name: str) -> dict:
    return {"units": units, "long_name": long_name}


def run_lucky(iter_chunks: Callable[[], Iterable[tuple[int, np.ndarray]]], n_frames: int,
              detectors: Sequence[Detector], fractions: Sequence[float],
              diffraction_limited_peak: float, pixel_scale_arcsec: float, seed: int,
              criteria_external: Sequence[ExternalCriterion] = (),
              image_crop_px: int | None = 64,
              progress_interval_s: float = 5.0) -> xr.Dataset:
    """Lucky imaging of one frame cube for several detectors, criteria and fractions.

    ``iter_chunks()`` returns a fresh iterator of ``(start, frames)``: ``frames``
    (k, n, n) float32 noiseless unit-flux images of frames ``start..start+k-1``, in
    order; it is called twice. ``diffraction_limited_peak``: the Strehl reference
    (``Imager.diffraction_limited_peak``) for unit flux at this sampling;
    ``pixel_scale_arcsec`` [arcsec/pixel]. Criteria: ``strehl`` and ``d50`` of each
    noisy frame, then ``criteria_external`` (each (n_frames,)).

    Pass 1 applies each detector's noise (rng ``default_rng([seed,
    detector_key(name), start])`` (:func:`detector_key`): a detector's draws depend on the
    seed and its name only, not on the other detectors, so detector names must be
    distinct), measures per-frame Strehl, d50 and centre of gravity, and sums the
    long exposure without recentring. Frames are then ranked
    per criterion (:func:`rank_frames`) and assigned to nested bins
    (:func:`selection_bins`). Pass 2 regenerates the same noise, recentres each frame
    (:func:`recentring_shifts_px`, :func:`shift_frames`) and adds it into its
    (criterion, bin) partial sum with one matrix product per chunk, and into the
    recentred long exposure (all frames); each fraction's
    image is the cumulative sum of its bins. Alongside, the noiseless frames (the input,
    as float32) get the same detector's shifts (from the noisy centroids) and the same
    bins (from the noisy ranking) into a second set of partial sums: the ``*_noiseless``
    scores separate a wrong selection or recentring from the noise in the final image.
    For a noiseless detector both sets receive the very same products, so the
    ``*_noiseless`` values equal the others bit for bit. Both passes serve all
    detectors, so the frames are read twice in total. Memory: the two sets of partial
    sums, float64 (2 x detectors x criteria x distinct counts x n x n, the noiseless set
    doubling what the noisy one alone needs), plus one chunk and, when scoring, the
    integrated images (criteria x fractions x detectors x n x n) of one set at a time.

    Returns a CF-style :class:`xarray.Dataset`: ``strehl``, ``fwhm_arcsec``,
    ``d50_arcsec`` (criterion, fraction, detector) and the same of the noiseless frames
    with the same selection and shifts, ``strehl_noiseless``, ``fwhm_arcsec_noiseless``,
    ``d50_arcsec_noiseless``; ``long_exposure_strehl``,
    ``long_exposure_fwhm_arcsec``, ``long_exposure_d50_arcsec`` (recentring,
    detector); per-frame ``frame_strehl``, ``frame_d50_arcsec``,
    ``frame_centroid_px`` (detector, frame[, axis]) and ``frame_criterion``
    (criterion, detector, frame); unless ``image_crop_px`` is 0, the central
    ``image_crop_px`` square (None: whole frame) of the integrated images normalised
    to unit flux, ``image`` (criterion, fraction, detector, y, x) and
    ``long_exposure_image`` (recentring, detector, y, x).
    """
    detectors = list(detectors)
    counts = fraction_counts(n_frames, fractions)
    criteria = list(IMAGE_CRITERIA) + [(c.name, bool(c.larger_is_better))
                                       for c in criteria_external]
    for c in criteria_external:
        if np.shape(c.values) != (n_frames,):
            raise ValueError(f"criterion {c.name}: values must have shape ({n_frames},)")
    n_det, n_crit = len(detectors), len(criteria)
    names = [d.name for d in detectors]
    if len(set(names)) != n_det or len({detector_key(name) for name in names}) != n_det:
        raise ValueError(f"detector names must be distinct (and their crc32 too): {names}")

    # pass 1: per-frame metrics and centroids, long exposure without recentring
    frame_strehl = np.full((n_det, n_frames), np.nan)
    frame_d50_px = np.full((n_det, n_frames), np.nan)
    frame_centroid = np.full((n_det, n_frames, 2), np.nan)
    frame_flux = np.full((n_det, n_frames), np.nan)
    encircled = long_none = long_cog = None
    progress = Progress("lucky pass 1/2: frames", n_frames, progress_interval_s)
    for start, frames in _chunks(iter_chunks, n_frames):
        n = frames.shape[-1]
        if encircled is None:
            encircled = EncircledEnergy(n)
            long_none = np.zeros((n_det, n, n))
            long_cog = np.zeros((n_det, n, n))
        sl = slice(start, start + len(frames))
        for i, detector in enumerate(detectors):
            noisy = _noisy(frames, detector, seed, start)
            centroids = centroid_px(noisy)
            frame_centroid[i, sl] = centroids
            frame_flux[i, sl] = noisy.sum(axis=(-2, -1), dtype=np.float64)
            frame_strehl[i, sl] = strehl(noisy, diffraction_limited_peak)
            frame_d50_px[i, sl] = encircled.radius_px(noisy, centres_px=centroids) * 2
            long_none[i] += noisy.sum(axis=0, dtype=np.float64)
        progress.update(sl.stop)
    frame_d50_arcsec = frame_d50_px * pixel_scale_arcsec
    shifts = recentring_shifts_px(frame_centroid, n)

    # ranking: per detector and criterion, frames to nested bins
    values = np.empty((n_crit, n_det, n_frames))
    values[0], values[1] = frame_strehl, frame_d50_arcsec
    for j, c in enumerate(criteria_external):
        values[2 + j] = np.asarray(c.values, dtype=np.float64)[None, :]
    n_bins = len(np.unique(counts))
    bin_of_frame = np.empty((n_det, n_crit, n_frames), dtype=np.int64)
    for i in range(n_det):
        for c, (_, larger) in enumerate(criteria):
            order = rank_frames(values[c, i], larger)
            bin_of_frame[i, c], last_bin = selection_bins(order, counts)

    # pass 2: same noise, recentre, accumulate into (criterion, bin) partial sums
    partial = np.zeros((n_det, n_crit * n_bins, n * n))
    partial_noiseless = np.zeros((n_det, n_crit * n_bins, n * n))
    around = n // 2 + np.arange(-3, 4)
    centre_window = (around[:, None] * n + around).ravel()  # 7 x 7 pixels around the axis
    frame_window = np.empty((n_det, n_frames, centre_window.size), dtype=np.float32)
    rows = np.arange(n_crit)[:, None] * n_bins  # row offset of each criterion
    progress = Progress("lucky pass 2/2: frames", n_frames, progress_interval_s)
    for start, frames in _chunks(iter_chunks, n_frames):
        k = len(frames)
        sl = slice(start, start + k)
        noiseless = None
        for i, detector in enumerate(detectors):
            noisy = _noisy(frames, detector, seed, start)
            if not np.array_equal(noisy.sum(axis=(-2, -1), dtype=np.float64), frame_flux[i, sl]):
                raise RuntimeError(f"frames {start}.. differ between the two passes")
            flat = shift_frames(noisy, shifts[i, sl]).reshape(k, n * n)
            bins = bin_of_frame[i][:, sl]  # (n_crit, k)
            one_hot = np.zeros((n_crit * n_bins, k), dtype=np.float32)
            kept = bins >= 0
            _, frame_index = np.nonzero(kept)
            one_hot[(rows + bins)[kept], frame_index] = 1.0
            summed = one_hot @ flat
            partial[i] += summed
            if not detector.noiseless:  # the noiseless frames, same shifts and bins
                if noiseless is None:  # what a noiseless detector gives (apply_detector)
                    noiseless = np.asarray(frames, dtype=np.float32)
                summed = one_hot @ shift_frames(noiseless, shifts[i, sl]).reshape(k, n * n)
            partial_noiseless[i] += summed
            long_cog[i] += flat.sum(axis=0, dtype=np.float64).reshape(n, n)
            frame_window[i, sl] = flat[:, centre_window]
        progress.update(sl.stop)
    frame_recentred_strehl = _value_at_peak(frame_window, centre_window, long_cog, frame_flux,
                                            diffraction_limited_peak)

    # integrated images: cumulative sums of bins, scored
    scoring = (n, n_bins, last_bin, encircled, diffraction_limited_peak, pixel_scale_arcsec)
    _, s_nl, fwhm_nl, d50_nl = _score(partial_noiseless, *scoring)
    del partial_noiseless
    images, s_int, fwhm_int, d50_int = _score(partial, *scoring)
    del partial
    long_images = np.stack([long_none, long_cog])  # (recentring, det, n, n)
    s_long = strehl(long_images, diffraction_limited_peak)
    d50_long = 2 * encircled.radius_px(long_images) * pixel_scale_arcsec
    fwhm_long = fwhm_arcsec(long_images, pixel_scale_arcsec)

    ds = _dataset(detectors, criteria, criteria_external, fractions, counts, n_frames,
                  s_int, fwhm_int, d50_int, s_long, fwhm_long, d50_long,
                  frame_strehl, frame_d50_arcsec, frame_centroid, values)
    same = "of the integrated image of the same selection and shifts applied to the noiseless frames"
    sel = ("criterion", "fraction", "detector")
    ds["strehl_noiseless"] = (sel, s_nl, _attrs("1", f"Strehl ratio {same}"))
    ds["fwhm_arcsec_noiseless"] = (sel, fwhm_nl, _attrs("arcsec", f"FWHM {same}"))
    ds["d50_arcsec_noiseless"] = (sel, d50_nl, _attrs(
        "arcsec", f"diameter enclosing 50% of the energy {same}"))
    ds["frame_recentred_strehl"] = (("detector", "frame"), frame_recentred_strehl, _attrs(
        "1", "recentred frame's value at the recentred long exposure's peak pixel (within 3 pixels of the axis) "
             "over its flux and the diffraction-limited peak (their mean is that long exposure's Strehl)"))
    if image_crop_px != 0:
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = images / images.sum(axis=(-2, -1), keepdims=True)
            unit_long = long_images / long_images.sum(axis=(-2, -1), keepdims=True)
        unit, unit_long = _crop(unit, image_crop_px), _crop(unit_long, image_crop_px)
        m = unit.shape[-1]
        offsets = np.arange(m) - m // 2
        ds = ds.assign_coords(
            y=("y", offsets, _attrs("pixel", "row offset from the optical axis pixel (n/2)")),
            x=("x", offsets, _attrs("pixel", "column offset from the optical axis pixel (n/2)")))
        ds["image"] = (("criterion", "fraction", "detector", "y", "x"), unit.astype(np.float32),
                       _attrs("1", "integrated image normalised to unit flux"))
        ds["long_exposure_image"] = (("recentring", "detector", "y", "x"),
                                     unit_long.astype(np.float32),
                                     _attrs("1", "long exposure (all frames), unit flux"))
    ds.attrs.update(pixel_scale_arcsec=pixel_scale_arcsec,
                    diffraction_limited_peak=diffraction_limited_peak, seed=seed,
                    n_pixels=n)
    return ds


def _value_at_peak(frame_window: np.ndarray, window: np.ndarray, long_images: np.ndarray,
                   frame_flux: np.ndarray, diffraction_limited_peak: float) -> np.ndarray:
    """Per detector and frame, ``frame[p] / (flux P_dl)`` at the brightest pixel ``p`` of
    the long exposure (``long_images`` (det, n, n)) among the pixels ``window`` (flat
    indices, around the axis), from the frames' values there (``frame_window``). When
    ``p`` is the long exposure's peak and the fluxes are equal, their mean is its
    Strehl (:func:`.metrics.strehl`)."""
    out = np.empty(frame_flux.shape)
    for i, image in enumerate(long_images):
        k = np.argmax(image.ravel()[window])
        with np.errstate(invalid="ignore", divide="ignore"):
            out[i] = frame_window[i, :, k] / (frame_flux[i] * diffraction_limited_peak)
    return out


def _dataset(detectors, criteria, criteria_external, fractions, counts, n_frames,
             s_int, fwhm_int, d50_int, s_long, fwhm_long, d50_long,
             frame_strehl, frame_d50_arcsec, frame_centroid, values) -> xr.Dataset:
    """Assemble the CF-style result dataset of :func:`run_lucky`."""
    external = {c.name: c for c in criteria_external}
    criterion_units = ["1", "arcsec"] + [external[name].units for name, _ in criteria[2:]]
    photons = [np.nan if d.photons_per_frame is None else d.photons_per_frame for d in detectors]
    coords = {
        "criterion": ("criterion", [name for name, _ in criteria],
                      _attrs("1", "frame selection criterion")),
        "larger_is_better": ("criterion", np.array([int(lb) for _, lb in criteria], np.int8),
                             {**_attrs("1", "criterion ranks larger values first"),
                              "flag_values": np.array([0, 1], np.int8),
                              "flag_meanings": "smaller_is_better larger_is_better"}),
        "criterion_units": ("criterion", criterion_units, _attrs("1", "units of the criterion")),
        "fraction": ("fraction", np.asarray(fractions, dtype=np.float64),
                     _attrs("1", "fraction of frames selected")),
        "n_frames_selected": ("fraction", counts, _attrs("1", "number of frames selected")),
        "detector": ("detector", [d.name for d in detectors], _attrs("1", "detector model")),
        "photons_per_frame": ("detector", np.array(photons, np.float64),
                              _attrs("photon", "detected photons per frame (NaN: noiseless)")),
        "read_noise_e": ("detector", np.array([d.read_noise_e for d in detectors], np.float64),
                         _attrs("electron", "read noise rms per pixel")),
        "recentring": ("recentring", ["none", "cog"],
                       _attrs("1", "recentring of the long exposure: none or centre of gravity")),
        "frame": ("frame", np.arange(n_frames), _attrs("1", "frame index")),
        "axis": ("axis", ["y", "x"], _attrs("1", "image axis")),
    }
    sel = ("criterion", "fraction", "detector")
    data = {
        "strehl": (sel, s_int, _attrs("1", "Strehl ratio of the integrated image")),
        "fwhm_arcsec": (sel, fwhm_int, _attrs("arcsec", "FWHM of the integrated image")),
        "d50_arcsec": (sel, d50_int, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the integrated image")),
        "long_exposure_strehl": (("recentring", "detector"), s_long,
                                 _attrs("1", "Strehl ratio of the long exposure")),
        "long_exposure_fwhm_arcsec": (("recentring", "detector"), fwhm_long,
                                      _attrs("arcsec", "FWHM of the long exposure")),
        "long_exposure_d50_arcsec": (("recentring", "detector"), d50_long, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the long exposure")),
        "frame_strehl": (("detector", "frame"), frame_strehl,
                         _attrs("1", "Strehl ratio of the detected frame")),
        "frame_d50_arcsec": (("detector", "frame"), frame_d50_arcsec, _attrs(
            "arcsec", "diameter enclosing 50% of the energy of the detected frame")),
        "frame_centroid_px": (("detector", "frame", "axis"), frame_centroid, _attrs(
            "pixel", "centre of gravity of the detected frame (pixel index)")),
        "frame_criterion": (("criterion", "detector", "frame"), values, _attrs(
            "1", "per-frame criterion value (units: criterion_units)")),
    }
    return xr.Dataset(data, coords=coords)
