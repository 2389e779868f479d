"""Every random stream of the study, derived from its one seed.

* Phase screens: layer ``i`` draws from ``default_rng([seed, i])`` (:func:`screen_rng`).
* LGS WFS noise (photon and read noise of every exposure): ``default_rng([seed,
  WFS_NOISE_STREAM])`` (:func:`wfs_noise_rng`); the tag lies above every layer index, so the
  WFS noise never replays a layer's numbers (``SeedSequence`` ignores trailing zero words, so
  the streams differ by a nonzero word, not by their length).
* WFS calibration (the turbulence draws of its dithers): ``default_rng([seed,
  CALIBRATION_STREAM])`` (:func:`calibration_rng`); the layer indices stay below its tag.
* Layer strengths in time (``atmosphere.layer_variability``): layer ``i``'s log-normal process
  draws from ``default_rng([seed, LAYER_STRENGTH_STREAM, i])`` (:func:`layer_strength_rng`),
  ``seed`` the block's own (by default the study's).
* Lucky-camera detector noise: target ``t`` of a case uses the seed ``seed + t``
  (:func:`target_seed`), and frame ``f`` of detector ``name`` draws from compiled streams keyed
  by ``(seed + t, detector_key(name), f)``: the three words are this module's, the
  generators' seeding from them (:func:`luckyao.lucky.noise_streams.stream_key`) is part of the
  compiled generators, as ``SeedSequence`` is of numpy's (a splitmix64 / xoshiro256++
  family of its own). An EMCCD's gain register and
  input-referred read noise of that frame: ``default_rng([seed + t, EMCCD_STREAM,
  detector_key(name), f])`` (:func:`emccd_rng`).
"""

import zlib

import numpy as np

WFS_NOISE_STREAM = 0xFFFF_FFFF
"""Second entropy word of the WFS-noise stream: above any layer index of the screens."""


CALIBRATION_STREAM = 1000
"""Second entropy word of the WFS calibration's stream: above any layer index of the screens."""


def screen_rng(seed: int, layer: int) -> np.random.Generator:
    """The generator of layer ``layer``'s phase screen."""
    if not 0 <= layer < CALIBRATION_STREAM:
        raise ValueError(f"layer index {layer} out of [0, {CALIBRATION_STREAM})")
    return np.random.default_rng([seed, layer])


def wfs_noise_rng(seed: int) -> np.random.Generator:
    """The generator of the LGS wavefront sensors' photon and read noise."""
    return np.random.default_rng([seed, WFS_NOISE_STREAM])


def calibration_rng(seed: int) -> np.random.Generator:
    """The generator of the WFS calibration's turbulence draws."""
    return np.random.default_rng([seed, CALIBRATION_STREAM])


LAYER_STRENGTH_STREAM = 0xFFFF_FFFD
"""Second entropy word of the layer-strength streams (differs from every other stream's)."""


def layer_strength_rng(seed: int, layer: int) -> np.random.Generator:
    """The generator of layer ``layer``'s strength in time (:mod:`luckyao.atmosphere.intermittency`)."""
    return np.random.default_rng([seed, LAYER_STRENGTH_STREAM, layer])


EMCCD_STREAM = 0xFFFF_FFFE
"""Second entropy word of the EMCCD gain-register streams (differs from every other stream's)."""


def emccd_rng(seed: int, key: int, frame: int) -> np.random.Generator:
    """The generator of an EMCCD's gain register and read noise for frame ``frame`` of the
    detector keyed ``key`` (:func:`detector_key`), target seed ``seed``."""
    return np.random.default_rng([seed, EMCCD_STREAM, key, frame])


def target_seed(seed: int, target: int) -> int:
    """The seed of target ``target``'s lucky-camera detector noise."""
    return seed + target


def detector_key(name: str) -> int:
    """Stable integer of a detector's name that keys its noise: ``zlib.crc32`` of its UTF-8.

    Not Python's ``hash`` (salted per process), so draws are reproducible across runs.
    """
    return zlib.crc32(name.encode("utf-8"))
