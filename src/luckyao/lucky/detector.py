"""Lucky-camera detector model: photon shot noise and Gaussian read noise, optionally an EMCCD.

As in the study (Basden 2014): the signal is given as detected photons per frame, so
there is no quantum efficiency, no bias and no gain; a pixel reads
``Poisson(N I) + Normal(0, sigma_read)`` electrons, ``I`` the unit-flux image and ``N``
the photons per frame.

An electron-multiplying CCD (``electron_multiplying``) multiplies a pixel's ``n`` electrons
in its gain register: at high gain ``g`` the output is ``g Gamma(n, 1)`` (the sum of ``n``
exponential gains; Basden, Haniff & Mackay 2003), read here referred to the input (divided by
``g``), so the read noise is the input-referred ``sigma_read``: a pixel reads
``Gamma(Poisson(N I), 1) + Normal(0, sigma_read)``, mean ``N I``, variance ``2 N I + sigma^2``
(excess-noise factor sqrt 2: the signal-to-noise of half the photons without it, the paper's
"effectively halves the quantum efficiency"). With ``photon_counting_threshold_e`` each
pixel reads 1 above the threshold and 0 below (photon counting; coincidence losses above
~0.1 photon per pixel per frame).

The model is sampled by :class:`KeyedNoise`, from compiled streams keyed per frame by
(seed, detector name, frame index) (:mod:`luckyao.lucky.noise_streams`); the tests hold a plain
numpy sampler of the same model as its reference.
"""

from dataclasses import dataclass

import numpy as np

from ..seeds import detector_key, emccd_rng
from . import noise_streams


@dataclass(frozen=True)
class Detector:
    """A detector model; ``photons_per_frame=None`` is the noiseless camera.

    ``photons_per_frame`` [photon per frame]: detected photons from the target in one
    frame (the mean flux of the noisy frame). ``read_noise_e`` [electron rms per pixel
    per frame]: standard deviation of the Gaussian read noise (an EMCCD's, referred to the
    input). ``electron_multiplying``: an EMCCD's gain register (module docstring);
    ``photon_counting_threshold_e`` [electron, input-referred]: count photons (EMCCD only).
    """

    name: str
    photons_per_frame: float | None = None
    read_noise_e: float = 0.0
    electron_multiplying: bool = False
    photon_counting_threshold_e: float | None = None

    def __post_init__(self):
        if self.photons_per_frame is None:
            if self.read_noise_e != 0.0:
                raise ValueError("a noiseless detector (photons_per_frame=None) has no read noise")
        elif not self.photons_per_frame > 0:
            raise ValueError(f"photons_per_frame must be > 0, got {self.photons_per_frame}")
        if not self.read_noise_e >= 0:
            raise ValueError(f"read_noise_e must be >= 0, got {self.read_noise_e}")
        if self.electron_multiplying and self.photons_per_frame is None:
            raise ValueError(f"detector {self.name!r}: a noiseless detector has no gain register")
        if self.photon_counting_threshold_e is not None and not (
            self.electron_multiplying and self.photon_counting_threshold_e > 0
        ):
            raise ValueError(
                f"detector {self.name!r}: photon_counting_threshold_e needs electron_multiplying "
                f"and must be > 0, got {self.photon_counting_threshold_e}"
            )

    @property
    def noiseless(self) -> bool:
        return self.photons_per_frame is None


class KeyedNoise:
    """Detector noise of frame chunks with one random stream per (seed, detector, frame).

    A pixel reads ``Poisson(N I) + sigma Normal(0, 1)`` (negative unit-flux values as 0),
    drawn by :func:`luckyao.lucky.noise_streams.detect_frames`: frame ``f``'s draws are keyed by
    ``(seed, detector_key(name), f)`` only, so they do not depend on the chunking, the other
    frames or the other detectors, and drawing a chunk again gives the same frames.
    :meth:`prepare` a chunk once (its cumulative sums, shared by all detectors): it returns the
    :class:`PreparedChunk` that detects it, valid until the next :meth:`prepare`.
    """

    def __init__(self, n_pixels: int, max_frames: int):
        n = n_pixels
        self.n_pixels, self.max_frames = n, max_frames
        self._within = np.empty((max_frames, n, n))
        self._rows_cumulative = np.empty((max_frames, n))
        self._bits = np.empty(n * n // 2 + noise_streams.LANES * 4, np.uint64)[: n * n // 2]
        self._normals = np.empty(n * n, np.float32)
        self._prepared = 0  # chunks prepared so far: only the last one's sums are held

    def prepare(self, frames_unit_flux: np.ndarray) -> "PreparedChunk":
        """The chunk of unit-flux frames (k, n, n) (float32, as given or converted), ready to detect."""
        unit = np.ascontiguousarray(frames_unit_flux, dtype=np.float32)
        k, n, _ = unit.shape
        if n * n % 64 or k > len(self._within) or n != self.n_pixels:
            raise ValueError(
                f"chunk {unit.shape}: n^2 must be a multiple of 64, frames {self.n_pixels} square, "
                f"at most {len(self._within)} of them"
            )
        noise_streams.cumulative(unit, self._within[:k], self._rows_cumulative[:k])
        self._prepared += 1
        return PreparedChunk(self, unit, self._prepared)


class PreparedChunk:
    """A chunk of unit-flux frames whose sums :class:`KeyedNoise` holds (until it prepares another)."""

    def __init__(self, noise: KeyedNoise, unit: np.ndarray, number: int):
        self._noise, self.unit, self._number = noise, unit, number

    def detect(
        self,
        detector: Detector,
        seed: int,
        first_frame: int,
        out: np.ndarray | None = None,
        drawn: np.ndarray | None = None,
    ) -> tuple[np.ndarray, ...]:
        """The chunk's detected frames [electron] (k, n, n) float32 (``out`` if given), frames
        ``first_frame..``, with their row and column sums (k, n) float64 and peak (k,) float32.
        A noisy detector only. With ``drawn`` (k,) bool, only those frames are drawn (the same
        draws as when all are): the others' values are undefined."""
        noise = self._noise
        if self._number != noise._prepared:
            raise RuntimeError("this chunk's sums were replaced: detect a chunk before preparing the next")
        if detector.noiseless:
            raise ValueError("a noiseless detector draws nothing")
        unit = self.unit
        k, n, _ = unit.shape
        out = np.empty(unit.shape, np.float32) if out is None else out[:k]
        if out.shape != unit.shape or out.dtype != np.float32 or not out.flags.c_contiguous:
            raise ValueError(f"out must be C-contiguous float32 of at least {unit.shape}")
        rows, cols, peak = np.empty((k, n)), np.empty((k, n)), np.empty(k, np.float32)
        drawn = np.ones(k, np.bool_) if drawn is None else np.asarray(drawn, np.bool_)
        em = detector.electron_multiplying
        noise_streams.detect_frames(
            unit,
            noise._within[:k],
            noise._rows_cumulative[:k],
            float(detector.photons_per_frame),
            np.float32(0.0 if em else detector.read_noise_e),
            seed,
            detector_key(detector.name),
            first_frame,
            drawn,
            out,
            rows,
            cols,
            peak,
            noise._bits,
            noise._normals,
        )
        if em:
            for j in np.flatnonzero(drawn):
                out[j] = gain_register(out[j], detector, emccd_rng(seed, detector_key(detector.name), first_frame + j))
                noise_streams.frame_sums(out[j : j + 1], rows[j : j + 1], cols[j : j + 1], peak[j : j + 1])
        return out, rows, cols, peak


def gain_register(electrons: np.ndarray, detector: Detector, rng: np.random.Generator) -> np.ndarray:
    """An EMCCD frame referred to the input (float32) of a frame's photo-electron counts:
    ``Gamma(n, 1) + Normal(0, sigma_read)`` per pixel, thresholded to 0 or 1 when photon counting
    (module docstring)."""
    signal = rng.standard_gamma(electrons.astype(np.float64))  # shape 0: exactly 0
    signal += rng.normal(0.0, detector.read_noise_e, signal.shape) if detector.read_noise_e else 0.0
    if detector.photon_counting_threshold_e is not None:
        signal = signal > detector.photon_counting_threshold_e
    return signal.astype(np.float32)
