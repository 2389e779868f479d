"""Lucky-camera detector model: photon shot noise and Gaussian read noise.

As in the study (Basden 2014): the signal is given as detected photons per frame, so
there is no quantum efficiency, no EMCCD excess noise factor, no bias and no gain; a
pixel reads ``Poisson(N I) + Normal(0, sigma_read)`` electrons, ``I`` the unit-flux
image and ``N`` the photons per frame.

Two samplers of that model: :func:`apply_detector` draws from a numpy ``Generator``;
:class:`KeyedNoise` (:func:`detect`), used by lucky imaging, from compiled streams keyed
per frame by (seed, detector name, frame index) (:mod:`luckyao.lucky.kernels`).
"""

import zlib
from dataclasses import dataclass

import numpy as np

from . import kernels


@dataclass(frozen=True)
class Detector:
    """A detector model; ``photons_per_frame=None`` is the noiseless camera.

    ``photons_per_frame`` [photon per frame]: detected photons from the target in one
    frame (the mean flux of the noisy frame). ``read_noise_e`` [electron rms per pixel
    per frame]: standard deviation of the Gaussian read noise.
    """

    name: str
    photons_per_frame: float | None = None
    read_noise_e: float = 0.0

    def __post_init__(self):
        if self.photons_per_frame is None:
            if self.read_noise_e != 0.0:
                raise ValueError("a noiseless detector (photons_per_frame=None) has no read noise")
        elif not self.photons_per_frame > 0:
            raise ValueError(f"photons_per_frame must be > 0, got {self.photons_per_frame}")
        if not self.read_noise_e >= 0:
            raise ValueError(f"read_noise_e must be >= 0, got {self.read_noise_e}")

    @property
    def noiseless(self) -> bool:
        return self.photons_per_frame is None


def apply_detector(frames_unit_flux: np.ndarray, detector: Detector,
                   rng: np.random.Generator) -> np.ndarray:
    """Detected frames [electron] (float32, same shape) from unit-flux frames (..., n, n).

    Each pixel: ``Poisson(N * I) + sigma * Normal(0, 1)``, ``N`` =
    ``detector.photons_per_frame``, ``sigma`` = ``detector.read_noise_e``; so the mean
    is ``N I`` and the variance ``N I + sigma^2``. Negative unit-flux values (rounding)
    are clipped to 0. A noiseless detector returns a float32 copy of the unit-flux
    frames (not scaled) and draws nothing from ``rng``. The input is never modified.

    Independent Poisson pixels are drawn in one of two equivalent ways (a Poisson
    process: the total ``K ~ Poisson(N sum I)`` and, given ``K``, photons
    independently in pixel ``p`` with probability ``I_p / sum I``, e.g. Feller vol. 1,
    sec. VI.6): per photon (inverse-CDF sampling, then counting) when a frame holds fewer
    than ``n_pixels / 16`` photons (faster there: ~0.2 us per photon against ~0.05 us
    per pixel); per pixel otherwise.
    """
    frames = np.asarray(frames_unit_flux)
    if detector.noiseless:
        return np.array(frames, dtype=np.float32, copy=True)
    if frames.min() < 0:
        frames = np.maximum(frames, 0)
    if detector.photons_per_frame < frames.shape[-1] * frames.shape[-2] / 16:
        electrons = _poisson_by_photons(frames, detector.photons_per_frame, rng)
    else:
        electrons = rng.poisson(frames.astype(np.float64) * detector.photons_per_frame)
        electrons = electrons.astype(np.float32)
    if detector.read_noise_e > 0:
        electrons += np.float32(detector.read_noise_e) * rng.standard_normal(
            electrons.shape, dtype=np.float32)
    return electrons


def _poisson_by_photons(frames: np.ndarray, photons: float,
                        rng: np.random.Generator) -> np.ndarray:
    """Independent Poisson counts (float32) of means ``photons * frames`` (..., n, n), frames >= 0.

    Per frame ``j``: ``K_j ~ Poisson(photons * sum frames_j)`` photons, each placed at the
    pixel whose interval of the normalised cumulative sum (float64) holds a uniform
    deviate; the CDFs of all frames are laid end to end (frame ``j`` on ``[j, j + 1]``)
    so one sorted search serves the whole batch.
    """
    shape = frames.shape
    flat = frames.reshape(-1, shape[-2] * shape[-1])
    k, m = flat.shape
    cdf = np.cumsum(flat, axis=1, dtype=np.float64)
    totals = cdf[:, -1].copy()
    n_photons = rng.poisson(photons * totals)
    with np.errstate(invalid="ignore", divide="ignore"):
        cdf /= totals[:, None]
    cdf[:, -1] = 1.0  # exact end of each frame's interval
    cdf += np.arange(k)[:, None]
    frame_of_photon = np.repeat(np.arange(k), n_photons)
    position = frame_of_photon + rng.random(frame_of_photon.size)
    position = np.minimum(position, np.nextafter(frame_of_photon + 1.0, 0.0))
    pixel = np.searchsorted(cdf.ravel(), position, side="right")
    counts = np.bincount(pixel, minlength=k * m)
    return counts.astype(np.float32).reshape(shape)


def detector_key(name: str) -> int:
    """Stable integer of a detector's name that keys its noise: ``zlib.crc32`` of its UTF-8.

    Not Python's ``hash`` (salted per process), so draws are reproducible across runs.
    """
    return zlib.crc32(name.encode("utf-8"))


class KeyedNoise:
    """Detector noise of frame chunks with one random stream per (seed, detector, frame).

    The same model as :func:`apply_detector` (``Poisson(N I) + sigma Normal(0, 1)``, negative
    unit-flux values as 0), drawn by :func:`luckyao.lucky.kernels.detect_frames`: frame
    ``f``'s draws are keyed by ``(seed, detector_key(name), f)`` only, so they do not
    depend on the chunking, the other frames or the other detectors, and drawing a chunk
    again gives the same frames. :meth:`prepare` a chunk once (sums shared by all
    detectors), then :meth:`detect` it for each detector.
    """

    def __init__(self, n_pixels: int, max_frames: int):
        n = n_pixels
        self.max_frames = max_frames
        self._within = np.empty((max_frames, n, n))
        self._rows_cumulative = np.empty((max_frames, n))
        self._bits = np.empty(n * n // 2 + kernels.LANES * 4, np.uint64)[: n * n // 2]
        self._normals = np.empty(n * n, np.float32)
        self._unit = None

    def prepare(self, frames_unit_flux: np.ndarray) -> None:
        """Take the chunk's unit-flux frames (k, n, n) (float32, as given or converted)."""
        unit = np.ascontiguousarray(frames_unit_flux, dtype=np.float32)
        k, n, _ = unit.shape
        if n * n % 64 or k > len(self._within):
            raise ValueError(f"chunk {unit.shape}: n^2 must be a multiple of 64, at most "
                             f"{len(self._within)} frames")
        kernels.cumulative(unit, self._within[:k], self._rows_cumulative[:k])
        self._unit = unit

    def detect(self, detector: Detector, seed: int, first_frame: int,
               out: np.ndarray | None = None, drawn: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """The prepared chunk's detected frames [electron] (k, n, n) float32 (``out`` if
        given), frames ``first_frame..``, with their row and column sums (k, n) float64
        and peak (k,) float32. A noisy detector only. With ``drawn`` (k,) bool, only those
        frames are drawn (the same draws as when all are): the others' values are undefined."""
        if detector.noiseless:
            raise ValueError("a noiseless detector draws nothing")
        unit = self._unit
        k, n, _ = unit.shape
        out = np.empty(unit.shape, np.float32) if out is None else out[:k]
        if out.shape != unit.shape or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be C-contiguous float32 of at least {unit.shape}")
        rows, cols, peak = np.empty((k, n)), np.empty((k, n)), np.empty(k, np.float32)
        drawn = np.ones(k, np.bool_) if drawn is None else np.asarray(drawn, np.bool_)
        kernels.detect_frames(unit, self._within[:k], self._rows_cumulative[:k],
                              float(detector.photons_per_frame), np.float32(detector.read_noise_e),
                              seed, detector_key(detector.name), first_frame, drawn, out, rows, cols, peak,
                              self._bits, self._normals)
        return out, rows, cols, peak


def detect(frames_unit_flux: np.ndarray, detector: Detector, seed: int,
           first_frame: int = 0) -> np.ndarray:
    """Detected frames (float32) of frames ``first_frame..`` (k, n, n) with the keyed
    streams of :class:`KeyedNoise` (a float32 copy for a noiseless detector)."""
    frames = np.asarray(frames_unit_flux)
    if detector.noiseless:
        return np.array(frames, dtype=np.float32, copy=True)
    noise = KeyedNoise(frames.shape[-1], len(frames))
    noise.prepare(frames)
    return noise.detect(detector, seed, first_frame)[0]
