"""The detector sweep of the noise study: its grid, its names, and where it is computed."""

from pathlib import Path

import numpy as np
import yaml

from luckyao.studyspec.lucky import lucky_settings, sweep_detectors
from luckyao.studyspec.study import validate_study

TINY = Path(__file__).parent / "data" / "tiny.yaml"


def test_sweep_is_a_log_grid_of_signal_for_every_read_noise():
    lucky = {"detector_sweep": {"photons_per_frame": {"min": 10, "max": 1e5, "levels": 9}, "read_noise_e": [0.1, 1.0]}}
    detectors = sweep_detectors(lucky)
    assert len(detectors) == 18
    for read_noise in (0.1, 1.0):
        photons = sorted(d["photons_per_frame"] for d in detectors.values() if d["read_noise_e"] == read_noise)
        np.testing.assert_allclose(photons, 10.0 ** np.arange(1, 5.5, 0.5), rtol=1e-12)  # half a decade apart
    assert "rn0.1_1e+03ph" in detectors and "rn1_31.6ph" in detectors
    assert sweep_detectors({}) == {}


def test_only_the_cases_a_noise_figure_shows_pay_for_the_sweep():
    study = yaml.safe_load(TINY.read_text())
    cases = validate_study(study)
    swept = set(sweep_detectors(study["lucky"]))
    with_sweep = lucky_settings(study, cases, "lgs")["detectors"]  # shown by the tiny 'noise' figure
    without = lucky_settings(study, cases, "good")["detectors"]
    assert swept <= set(with_sweep) and {"noiseless", "faint"} <= set(with_sweep)
    assert set(without) == {"noiseless", "faint"}
    # the registration methods too: every one where the sweep is drawn, cog alone elsewhere
    assert lucky_settings(study, cases, "lgs")["registration"] == ["cog", "xcorr"]
    assert lucky_settings(study, cases, "good")["registration"] == ["cog"]
