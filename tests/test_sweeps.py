"""Sweeps expand a grid of config values into named cases (reusing equal cases), and
configs with implausible values are warned about by key."""

import copy

import pytest

from luckyao.studyspec.schema import ConfigError, deep_merge, name_problem
from luckyao.studyspec.study import plausibility_warnings, unused_cases, validate_study
from luckyao.studyspec.sweeps import expand_study, sweep_points

from studies import tiny, with_sweep


def test_a_grid_is_every_combination_named_by_its_values_with_its_values_applied():
    study = with_sweep(
        {"atmosphere.r0_500nm_m": [0.1, 0.3], "camera.wavelength_m": [8e-7, 1.6e-6]},
        overrides={"wfs": {"n_subapertures": 4}},
    )
    cases = validate_study(study)
    points = sweep_points(study, "grid")
    names = [p.case for p in points]
    assert names == [
        "grid_r0_500nm_m-0.1_wavelength_m-8e-07",
        "grid_r0_500nm_m-0.1_wavelength_m-1.6e-06",
        "grid_r0_500nm_m-0.3_wavelength_m-8e-07",
        "grid_r0_500nm_m-0.3_wavelength_m-1.6e-06",
    ]
    for point in points:
        case = cases[point.case]
        assert case["atmosphere"]["r0_500nm_m"] == point.values["atmosphere.r0_500nm_m"]
        assert case["camera"]["wavelength_m"] == point.values["camera.wavelength_m"]
        assert case["wfs"]["n_subapertures"] == 4  # the sweep's overrides
        assert name_problem(point.case) is None
    assert expand_study(study)["figures"]["grid"]["cases"] == names


def test_a_point_equal_to_an_existing_case_is_that_case():
    """r0 = 0.2 m and 0.1 m over base are the tiny study's cases good and bad: not run twice."""
    study = with_sweep({"atmosphere.r0_500nm_m": [0.2, 0.1, 0.25]})
    names = [p.case for p in sweep_points(study, "grid")]
    assert names == ["good", "bad", "grid_r0_500nm_m-0.25"]
    assert set(validate_study(study)) == set(validate_study(tiny())) | {"grid_r0_500nm_m-0.25"}


def test_adding_values_keeps_the_other_points_names_and_configs():
    before = validate_study(with_sweep({"atmosphere.r0_500nm_m": [0.12, 0.25], "ao.mode": ["none"]}))
    after = validate_study(with_sweep({"atmosphere.r0_500nm_m": [0.12, 0.25, 0.3], "ao.mode": ["none"]}))
    assert set(after) - set(before) == {"grid_r0_500nm_m-0.3_mode-none"}
    assert all(after[name] == config for name, config in before.items())


def test_expanding_twice_changes_nothing():
    study = with_sweep({"atmosphere.r0_500nm_m": [0.12, 0.25]})
    once = expand_study(study)
    assert expand_study(once) == once


def test_a_key_the_overrides_add_can_be_swept():
    """``ao.apodisation`` is absent from base (no apodisation): the sweep's overrides add it,
    so its keys are swept; without the overrides the path is refused by key."""
    apodised = {
        "lgs": {"enabled": True},
        "ao": {"mode": "ltao", "apodisation": {"driver": "lgs", "blocked_fraction": 0.0}},
    }
    parameters = {"ao.apodisation.blocked_fraction": [0.0, 0.2], "ao.apodisation.driver": ["lgs", "oracle"]}
    cases = validate_study(with_sweep(parameters, overrides=apodised))
    points = sweep_points(with_sweep(parameters, overrides=apodised), "grid")
    assert [p.case for p in points][-1] == "grid_blocked_fraction-0.2_driver-oracle"
    assert cases[points[-1].case]["ao"]["apodisation"] == {"driver": "oracle", "blocked_fraction": 0.2}
    with pytest.raises(ConfigError, match=r"sweeps\.grid\.parameters\.ao\.apodisation\.driver"):
        validate_study(with_sweep({"ao.apodisation.driver": ["lgs"]}))


def test_two_parameters_with_one_last_part_are_named_by_their_paths():
    study = with_sweep({"camera.wavelength_m": [8e-7], "lgs.wavelength_m": [5.89e-7]})
    assert [p.case for p in sweep_points(study, "grid")] == ["grid_camera.wavelength_m-8e-07_lgs.wavelength_m-5.89e-07"]


@pytest.mark.parametrize(
    "parameters, key",
    [
        ({"atmosphere.r0_cm": [10]}, "sweeps.grid.parameters.atmosphere.r0_cm"),
        ({"atmosphere": [1]}, "sweeps.grid.parameters.atmosphere"),
        ({"atmosphere.r0_500nm_m": []}, "sweeps.grid.parameters.atmosphere.r0_500nm_m"),
    ],
)
def test_a_bad_sweep_is_refused_naming_its_key(parameters, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        validate_study(with_sweep(parameters))


def test_a_sweep_figure_needs_a_known_sweep_and_one_of_its_parameters():
    study = with_sweep({"atmosphere.r0_500nm_m": [0.12]})
    study["figures"]["grid"]["sweep"] = "nope"
    with pytest.raises(ConfigError, match=r"figures\.grid\.sweep"):
        validate_study(study)
    study = with_sweep({"atmosphere.r0_500nm_m": [0.12]})
    study["figures"]["grid"]["parameter"] = "ao.mode"
    with pytest.raises(ConfigError, match=r"figures\.grid\.parameter"):
        validate_study(study)


def test_a_value_that_cannot_name_a_case_is_refused():
    study = with_sweep({"lgs.profile": ["range gate"]})
    with pytest.raises(ConfigError, match=r"sweeps\.grid\.parameters"):
        validate_study(study)


def test_implausible_values_are_warned_about_by_key_and_stay_valid():
    """r0 written in cm as metres (10 m), a wavelength in nm as metres: both valid to the
    schema, both warned about, naming the key; the tiny study's values raise nothing."""
    study = tiny()
    assert plausibility_warnings(validate_study(study)) == []
    study["cases"]["good"]["atmosphere"]["r0_500nm_m"] = 10
    study["cases"]["bad"]["camera"] = {"wavelength_m": 800.0}
    warnings = plausibility_warnings(validate_study(study))
    assert len(warnings) == 2
    assert "cases.good.atmosphere.r0_500nm_m" in warnings[0] and "10 m" in warnings[0]
    assert "cases.bad.camera.wavelength_m" in warnings[1]


def test_cases_no_figure_shows_are_named():
    study = tiny()
    study["cases"]["spare"] = copy.deepcopy(study["cases"]["good"])
    assert unused_cases(expand_study(study)) == ["spare"]


def test_a_figure_draws_the_cases_its_patterns_match_in_the_configs_order():
    """cases_matching: after the figure's cases, pattern by pattern, each case once; an overlay's
    cases join; expanding twice changes nothing."""
    config = {
        "cases": {"noao_D4m": {}, "ltao_D4m": {}, "noao_D2m": {}, "ltao_sodium_D2m": {}, "other": {}},
        "figures": {
            "size": {
                "kind": "quality_vs_diameter",
                "cases": ["other"],
                "cases_matching": ["noao_D*", "ltao_D*", "*_D2m"],
            }
        },
    }
    expanded = expand_study(config)
    assert expanded["figures"]["size"]["cases"] == ["other", "noao_D4m", "noao_D2m", "ltao_D4m", "ltao_sodium_D2m"]
    assert expand_study(expanded) == expanded
    assert config["figures"]["size"]["cases"] == ["other"]  # a copy
    overlay = deep_merge(config, {"cases": {"noao_D39m": {}}})
    assert "noao_D39m" in expand_study(overlay)["figures"]["size"]["cases"]


@pytest.mark.parametrize("patterns", [["noao_D*", "glao_*"], "noao_D*", [""]])
def test_a_pattern_that_matches_no_case_is_refused_naming_the_key(patterns):
    config = {
        "cases": {"noao_D4m": {}},
        "figures": {"size": {"kind": "quality_vs_diameter", "cases_matching": patterns}},
    }
    with pytest.raises(ConfigError, match=r"figures\.size\.cases_matching"):
        expand_study(config)
