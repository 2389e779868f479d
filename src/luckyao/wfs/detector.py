"""The WFS detector's noise: photon (Poisson) and read (Gaussian) noise on the images."""

import numpy as np


def add_noise(
    images: np.ndarray, photons_per_subaperture: float, read_noise_e: float, rng: np.random.Generator
) -> np.ndarray:
    """Photon (Poisson) and read (Gaussian, ``read_noise_e`` rms) noise, new array.

    ``images`` are in units of a full sub-aperture's flux over the exposure
    (see :func:`.shack_hartmann.exposure_images`); ``photons_per_subaperture`` is the
    detected photon count of a full sub-aperture in one exposure.
    """
    expected = np.clip(images, 0, None) * photons_per_subaperture
    noisy = rng.poisson(expected).astype(np.float32)
    if read_noise_e > 0:
        noisy += rng.normal(0.0, read_noise_e, size=noisy.shape).astype(np.float32)
    return noisy / np.float32(photons_per_subaperture)
