"""Every random stream of the study comes from the seed (``luckyao.seeds``), and no two coincide."""

from pathlib import Path

import numpy as np
import pytest

from luckyao.lucky import noise_streams
from luckyao.seeds import CALIBRATION_STREAM, calibration_rng, detector_key, screen_rng, target_seed, wfs_noise_rng
from luckyao.studyspec.lucky import lucky_settings
from luckyao.studyspec.study import load_study


def _first_draws(rng: np.random.Generator) -> tuple:
    return tuple(rng.integers(0, 2**63, 4))


def test_no_two_numpy_streams_coincide():
    """The WFS noise is not a screen layer's stream (it was layer 1's: ``[seed, 1]``), for any
    layer index the screens could use, and the layers differ from one another."""
    for seed in (0, 1, 2014):
        draws = [_first_draws(screen_rng(seed, layer)) for layer in range(64)] + [
            _first_draws(wfs_noise_rng(seed)),
            _first_draws(calibration_rng(seed)),
        ]
        assert len(set(draws)) == len(draws)
        assert _first_draws(wfs_noise_rng(seed)) != _first_draws(np.random.default_rng([seed, 1]))
    with pytest.raises(ValueError):
        screen_rng(0, CALIBRATION_STREAM)  # no layer replays the calibration's stream


def test_the_calibration_draws_are_unchanged():
    """The WFS calibration still draws from ``default_rng([seed, 1000])`` (the calibrations of earlier runs)."""
    assert _first_draws(calibration_rng(2014)) == _first_draws(np.random.default_rng([2014, 1000]))


def test_todays_screens_are_unchanged():
    """Layer ``i`` still draws from ``default_rng([seed, i])`` (the screens of earlier runs)."""
    for layer in (0, 1, 8):
        assert _first_draws(screen_rng(2014, layer)) == _first_draws(np.random.default_rng([2014, layer]))


def test_no_two_detector_streams_coincide_in_the_default_study():
    """Every (target, detector, frame) of a default-study case gets its own stream key, and
    the keys of the first frames of every target and detector (the sweep's included) differ."""
    study, cases = load_study(Path(__file__).resolve().parents[1] / "config" / "config.yaml")
    name = next(f["cases"][0] for f in study["figures"].values() if f["kind"] == "quality_vs_signal")
    detectors = lucky_settings(study, cases, name)["detectors"]
    assert len(detectors) > 1
    keys = {
        noise_streams.stream_key(target_seed(study["seed"], t), detector_key(d), f)
        for t in range(3)
        for d in detectors
        for f in range(50)
    }
    assert len(keys) == 3 * len(detectors) * 50
