"""The detector sweep of the noise study: its grid, its names, and where it is computed."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from luckyao.studyspec.lucky import lucky_settings, sweep_detectors
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import validate_study
from luckyao.studyspec.sweeps import expand_study

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


def test_only_the_cases_the_config_lists_pay_for_the_sweep():
    study = yaml.safe_load(TINY.read_text())
    cases = validate_study(study)
    swept = set(sweep_detectors(study["lucky"]))
    with_sweep = lucky_settings(study, cases, "lgs")["detectors"]  # lucky.detector_sweep.cases: [lgs]
    without = lucky_settings(study, cases, "good")["detectors"]
    assert swept <= set(with_sweep) and {"noiseless", "faint"} <= set(with_sweep)
    assert set(without) == {"noiseless", "faint"}
    # the registration methods too: every one for the sweep's cases, cog alone elsewhere
    assert lucky_settings(study, cases, "lgs")["registration"] == ["cog", "xcorr"]
    assert lucky_settings(study, cases, "good")["registration"] == ["cog"]


def test_the_sweep_is_the_configs_not_the_figures():
    """A case gets the sweep because ``lucky.detector_sweep.cases`` lists it, whatever figures
    the study draws: with no figure at all, 'lgs' keeps it and 'good', listed, gets it."""
    study = yaml.safe_load(TINY.read_text())
    study["figures"] = {}
    study["lucky"]["detector_sweep"]["cases"] = ["lgs", "good"]
    cases = validate_study(study)
    swept = set(sweep_detectors(study["lucky"]))
    for name in ("lgs", "good"):
        assert swept <= set(lucky_settings(study, cases, name)["detectors"])
        assert lucky_settings(study, cases, name)["registration"] == ["cog", "xcorr"]
    assert lucky_settings(study, cases, "bad")["registration"] == ["cog"]
    del study["lucky"]["detector_sweep"]["cases"]  # the schema's default: no case
    assert lucky_settings(study, validate_study(study), "lgs")["registration"] == ["cog"]


def test_a_sweep_point_is_listed_by_its_case_name():
    study = yaml.safe_load(TINY.read_text())
    study["lucky"]["detector_sweep"]["cases"] = ["lgs", "r0_r0_500nm_m-0.15"]  # a point of the r0 sweep
    cases = validate_study(study)
    detectors = lucky_settings(expand_study(study), cases, "r0_r0_500nm_m-0.15")["detectors"]
    assert set(sweep_detectors(study["lucky"])) <= set(detectors)


@pytest.mark.parametrize("figure", ["noise", "registration", "limiting"])
def test_a_signal_figure_of_a_case_without_the_sweep_is_refused_by_key(figure):
    study = yaml.safe_load(TINY.read_text())
    study["figures"] = {figure: study["figures"][figure]}
    study["lucky"]["detector_sweep"]["cases"] = ["good"]
    with pytest.raises(ConfigError, match=rf"config key 'lucky\.detector_sweep\.cases': case 'lgs' .*'{figure}'"):
        validate_study(study)


def test_an_unknown_case_of_the_sweep_is_refused_by_key():
    study = yaml.safe_load(TINY.read_text())
    study["lucky"]["detector_sweep"]["cases"] = ["lgs", "nosuch"]
    with pytest.raises(ConfigError, match=r"config key 'lucky\.detector_sweep\.cases': unknown case 'nosuch'"):
        validate_study(study)
