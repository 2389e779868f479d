"""Telescope size as a study axis: the size-dependent keys derived from the diameter
(studyspec/scaling.py), the default study unchanged, and inconsistent input refused by key."""

import copy
from pathlib import Path

import pytest
import yaml

from luckyao.optics.imaging import Imager
from luckyao.studyspec.case import Case
from luckyao.studyspec.products import turbulence_spec
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import load_study, validate_study
from luckyao.units import ARCSEC_RAD

CONFIG = Path(__file__).resolve().parents[1] / "config" / "config.yaml"
PITCH_M = 0.525


@pytest.fixture(scope="module")
def study():
    return load_study(CONFIG)


def resolve(study, override: dict) -> dict:
    """The resolved config of one case ``override`` of the default study's base."""
    config = copy.deepcopy(study[0])
    config["cases"] = {"x": override}
    config["figures"] = {}
    config["lucky"]["detector_sweep"]["cases"] = []
    config.pop("sweeps", None)
    return validate_study(config)["x"]


def test_default_system_is_derived_as_written_before(study):
    """The 4.2 m base resolves to the values config.yaml wrote before they were derived:
    1.2 m obscuration, 8x8 WFS, 9x9 DM, 256 camera pixels (so no case changes)."""
    _, cases = study
    case = cases["ltao_r0_13.5cm"]
    assert case["telescope"] == {"diameter_m": 4.2, "obscuration_m": 1.2}
    assert case["wfs"]["n_subapertures"] == 8 and case["ao"]["n_actuators"] == 9
    assert case["camera"]["n_pixels"] == 256
    assert cases["ltao_wfs16"]["wfs"]["n_subapertures"] == 16 and cases["ltao_wfs16"]["ao"]["n_actuators"] == 9
    assert cases["ltao_dm5"]["ao"]["n_actuators"] == 5 and cases["ltao_dm5"]["wfs"]["n_subapertures"] == 8
    assert turbulence_spec(study[0], case)["min_across_m"] == 16.8


@pytest.mark.parametrize(
    "diameter_m, n_sub, obscuration_m", [(2.5, 5, 0.714), (4.2, 8, 1.2), (8.2, 16, 2.343), (10.4, 20, 2.971)]
)
def test_size_dependent_keys_follow_the_diameter(study, diameter_m, n_sub, obscuration_m):
    """At a constant pitch: round(D / 0.525 m) sub-apertures (pitch within 5 % of 0.525 m),
    a DM in Fried geometry, the obscuration 2/7 D, and a camera that samples lambda/D at
    800 nm with at least 2 (and under 2.15: the next fast FFT size) pixels over the 5" field,
    at least two pixels per pupil sample (no FFT oversampling); screens at least 4 D across
    the wind."""
    case = resolve(study, {"telescope": {"diameter_m": diameter_m}, "ao": {"mode": "ltao"}})
    assert case["wfs"]["n_subapertures"] == n_sub
    assert abs(diameter_m / n_sub - PITCH_M) < 0.05 * PITCH_M
    assert case["ao"]["n_actuators"] == n_sub + 1
    assert case["telescope"]["obscuration_m"] == obscuration_m
    camera = case["camera"]
    n_pixels = camera["n_pixels"]
    pixel_rad = camera["field_of_view_arcsec"] * ARCSEC_RAD / n_pixels
    per_lambda_over_d = camera["wavelength_m"] / diameter_m / pixel_rad
    assert n_pixels % 8 == 0 and 2.0 <= per_lambda_over_d < 2.15
    imager = Imager(Case.from_config(case).telescope, Case.from_config(case).camera)
    assert imager.oversampling == 1 and 2 * imager.grid.n_pix <= n_pixels
    assert imager.grid.dx_m == pytest.approx(camera["wavelength_m"] / (camera["field_of_view_arcsec"] * ARCSEC_RAD))
    assert turbulence_spec(study[0], case)["min_across_m"] == max(16.8, 4 * diameter_m)


def test_explicit_values_win(study):
    case = resolve(
        study,
        {
            "telescope": {"diameter_m": 8.2, "obscuration_m": 1.0},
            "wfs": {"n_subapertures": 8},
            "camera": {"n_pixels": 128},
        },
    )
    assert case["telescope"]["obscuration_m"] == 1.0 and case["wfs"]["n_subapertures"] == 8
    assert case["ao"]["n_actuators"] == 17 and case["camera"]["n_pixels"] == 128


def test_derivation_parameters_change_the_derived_values(study):
    case = resolve(
        study,
        {
            "telescope": {"diameter_m": 4.2, "subaperture_pitch_m": 0.2625, "obscuration_ratio": 0.1},
            "camera": {"pixels_per_lambda_over_d": 3.0},
        },
    )
    assert case["wfs"]["n_subapertures"] == 16 and case["ao"]["n_actuators"] == 17
    assert case["telescope"]["obscuration_m"] == 0.42
    assert case["camera"]["n_pixels"] == 384  # 3 x 127.3 = 381.8 -> 384


@pytest.mark.parametrize(
    "override, key",
    [
        ({"telescope": {"subaperture_pitch_m": 0.5}, "wfs": {"n_subapertures": 8}}, "cases.x.wfs.n_subapertures"),
        ({"telescope": {"subaperture_pitch_m": 0.5}, "ao": {"n_actuators": 9}}, "cases.x.ao.n_actuators"),
        ({"telescope": {"obscuration_m": 1.0, "obscuration_ratio": 0.2}}, "cases.x.telescope.obscuration_m"),
        ({"camera": {"n_pixels": 256, "pixels_per_lambda_over_d": 2.0}}, "cases.x.camera.n_pixels"),
        ({"telescope": {"diameter_m": 0.7}}, "cases.x.telescope.diameter_m"),
        ({"telescope": {"obscuration_ratio": 1.5}}, "cases.x.telescope.obscuration_ratio"),
        ({"telescope": {"subaperture_pitch_m": -0.5}}, "cases.x.telescope.subaperture_pitch_m"),
    ],
)
def test_inconsistent_sizes_are_refused_by_key(study, override, key):
    with pytest.raises(ConfigError, match=f"config key '{key}'"):
        resolve(study, override)


def test_a_diameter_sweep_derives_each_point(study):
    config = copy.deepcopy(study[0])
    config["sweeps"] = {"size": {"parameters": {"telescope.diameter_m": [2.5, 4.2, 8.2]}}}
    config["figures"] = {}
    cases = validate_study(config)
    assert cases["size_diameter_m-8.2"]["wfs"]["n_subapertures"] == 16
    assert cases["size_diameter_m-2.5"]["camera"]["n_pixels"] == 160  # 152 = 2^3 19 has a slow FFT
    assert "size_diameter_m-4.2" not in cases  # the base itself is noao_r0_13.5cm


def test_the_study_without_derivation_is_the_tiny_one():
    """A config that writes every size-dependent key (the tests' tiny study) keeps them."""
    tiny = yaml.safe_load((Path(__file__).parent / "data" / "tiny.yaml").read_text())
    case = validate_study(tiny)["good"]
    assert case["camera"]["n_pixels"] == 64 and case["telescope"]["obscuration_m"] == 1.2
