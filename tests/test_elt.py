"""The 39 m overlay (config/elt.yaml): what it derives, its beacons' geometry against the stated
choices, its jobs' estimates within 16 GB, and the clear refusals at that size. No time loop."""

from pathlib import Path

import numpy as np
import pytest

from luckyao.geometry import asterism_directions_rad, footprint_scale
from luckyao.io.hashing import sha256
from luckyao.jobs.resources import (
    MARGIN,
    calibration_memory_bytes,
    checked_study,
    study_jobs,
    wfs_pupil_samples,
)
from luckyao.studyspec.case import Case
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, read_study, validate_study
from luckyao.studyspec.view import resolve_study
from luckyao.units import ARCSEC_RAD
from luckyao.wfs.beacons import elongation_offsets_rad
from luckyao.wfs.sampling import calibration_screen_size

CONFIG = Path(__file__).resolve().parents[1] / "config"
ELT = (CONFIG / "config.yaml", CONFIG / "elt.yaml")
CASES = ("noao_D39m", "ltao_sodium_D39m")
JOB_LIMIT_BYTES = 16e9
"""Every 39 m job's declared memory at most this (issue 42)."""


@pytest.fixture(scope="module")
def elt():
    config, cases = load_study(*ELT)
    return config, cases


def test_the_overlay_derives_the_stated_system(elt):
    """74x74 sub-apertures, a 75x75 DM, a 960-pixel camera (2 px per lambda/D over 2"), the 11 m
    obscuration, six sodium beacons, the iterative tomography, 20 s."""
    _, cases = elt
    for name in CASES:
        case = cases[name]
        assert case["telescope"] == {"diameter_m": 39.0, "obscuration_m": 11.0}
        assert case["wfs"]["n_subapertures"] == 74 and case["ao"]["n_actuators"] == 75
        assert case["camera"]["n_pixels"] == 960
        # 2 px per lambda/D over the field: 2 x 39 m x 2" / 800 nm = 945.4, rounded up to 8 x 2^4 x 3 x 5 / 2
        assert 2 * 39.0 * 2.0 * ARCSEC_RAD / 8e-7 == pytest.approx(945.4, abs=0.1)
        assert case["tomography"]["method"] == "iterative" and case["wfs"]["model"] == "geometric"
        assert case["lgs"]["n_beacons"] == 6 and case["lgs"]["height_m"] == 90e3
        assert case["duration_s"] == 20.0 and case["atmosphere"]["r0_500nm_m"] == 0.135
        assert len(case["atmosphere"]["height_m"]) == 9
    assert cases["ltao_sodium_D39m"]["ao"]["mode"] == "ltao"
    assert cases["noao_D39m"]["ao"]["mode"] == "none" and cases["noao_D39m"]["lgs"]["enabled"]


def uncovered_m(case: dict, ring_diameter_arcsec: float, n_points: int = 3600) -> float:
    """How far [m] the on-axis target's metapupil at the highest layer reaches beyond the nearest
    beacon cone's footprint (<= 0: covered), over points on its rim and its centre."""
    lgs, diameter_m = case["lgs"], case["telescope"]["diameter_m"]
    height_m = max(case["atmosphere"]["height_m"])
    centres = asterism_directions_rad(lgs["n_beacons"], ring_diameter_arcsec, lgs["asterism_rotation_deg"]) * height_m
    radius_m = diameter_m / 2 * footprint_scale(height_m, lgs["height_m"])
    angle = np.linspace(0, 2 * np.pi, n_points, endpoint=False)
    points = np.vstack([diameter_m / 2 * np.column_stack([np.cos(angle), np.sin(angle)]), [[0.0, 0.0]]])
    nearest = np.min(np.linalg.norm(points[:, None, :] - centres[None], axis=-1), axis=1)
    return float(np.max(nearest - radius_m))


def test_the_beacon_ring_covers_the_on_axis_metapupil_at_the_highest_layer(elt):
    """The 60" ring covers it at 18 km with about a sub-aperture to spare; the ELT's 34-45" leave
    its rim between two beacons unseen, and 54" is the least that covers it."""
    _, cases = elt
    case = cases["ltao_sodium_D39m"]
    assert case["lgs"]["asterism_diameter_arcsec"] == 120.0
    assert -0.6 < uncovered_m(case, 120.0) < -0.3
    assert uncovered_m(case, 2 * 45.0) > 0.5 and uncovered_m(case, 2 * 34.0) > 1.0
    assert uncovered_m(case, 2 * 53.0) > 0 > uncovered_m(case, 2 * 55.0)
    # the beacons lie within the screens' field
    assert case["lgs"]["asterism_diameter_arcsec"] / 2 <= read_study(*ELT)["turbulence"]["field_radius_arcsec"]


def test_the_side_launch_elongation_fits_the_wfs_field(elt):
    """The sodium layer's FWHM (85-95 km) spans b (1/85 km - 1/95 km): 10.2" at the far edge's
    sub-aperture (a 39.7 m baseline), 0.33" at the near edge's; the WFS field (10 x 1.2") holds it."""
    _, cases = elt
    config = cases["ltao_sodium_D39m"]
    case = Case.from_config(config)
    wfs = case.shack_hartmann()
    lgs = config["lgs"]
    h, w = lgs["height_m"], lgs["profile_width_m"]
    ends = elongation_offsets_rad(wfs.subaperture_xy_m, case.lgs.launch_xy_m, h, [h - w / 2, h + w / 2])
    spread_arcsec = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=-1) / ARCSEC_RAD
    baselines = np.linalg.norm(wfs.subaperture_xy_m - case.lgs.launch_xy_m, axis=-1)
    expected = baselines * (1 / (h - w / 2) - 1 / (h + w / 2)) / ARCSEC_RAD
    np.testing.assert_allclose(spread_arcsec, expected, rtol=1e-9)
    assert spread_arcsec.max() == pytest.approx(10.2, abs=0.05)
    assert spread_arcsec.min() == pytest.approx(0.33, abs=0.02)
    field_arcsec = config["wfs"]["n_pixels"] * config["wfs"]["pixel_scale_arcsec"]
    assert field_arcsec == pytest.approx(12.0) and spread_arcsec.max() + 1.0 < field_arcsec
    assert wfs.grid.n_pix == wfs_pupil_samples(config) == 74 * 52  # one home for the sensor's sampling


def test_every_39m_job_is_declared_within_16_gb(elt):
    """Each job's estimate x the rules' margin (the lucky job's as is) at most 16 GB; the noAO
    case takes its lgs_rms from the LTAO case's slopes, so builds no tomography."""
    config, _ = elt
    view = checked_study(config, memory_bytes=64e9)  # the machine aside: the estimates themselves
    jobs = [job for job in study_jobs(view) if job.case in CASES]
    names = {job.name.split()[0] for job in jobs}
    assert {"turbulence", "slopes", "simulate", "lucky"} <= names
    assert not names & {"reconstructor", "commands", "calibration"}  # the geometric WFS: no calibration
    for job in jobs:
        margin = 1.0 if job.name.startswith(("lucky", "calibration")) else MARGIN
        assert margin * job.memory_bytes <= JOB_LIMIT_BYTES, job
        assert job.seconds > 0
    assert view.cases["noao_D39m"].lgs_twin == "ltao_sodium_D39m"
    slopes = next(job for job in jobs if job.name.startswith("slopes "))
    assert slopes.seconds < 120 and MARGIN * slopes.memory_bytes < 5e9  # geometric: ~10 ms per step
    simulate = {job.case: job for job in jobs if job.name.startswith("simulate ")}
    assert simulate["noao_D39m"].memory_bytes < simulate["ltao_sodium_D39m"].memory_bytes
    assert simulate["noao_D39m"].seconds < simulate["ltao_sodium_D39m"].seconds


def test_the_calibration_draws_are_capped_at_39m(elt):
    """A draw's screen is 4x the pupil up to 8192 samples (every existing sensor: unchanged), 2x
    beyond: the 39 m sensor's 3,848-sample pupil draws 8192^2, not 16,384^2 (~19 GB)."""
    config, _ = elt
    assert calibration_screen_size(128) == 512  # the default's 8 x 16 samples
    assert calibration_screen_size(30 * 14) == 2048  # 16 m, sodium
    assert calibration_screen_size(2048) == 8192
    assert calibration_screen_size(74 * 52) == 8192
    view = resolve_study(config, validate_study(config))
    assert view.cases["ltao_sodium_D39m"].calibration is None  # the overlay's geometric WFS
    physical = deep_merge(config, {"cases": {"ltao_sodium_D39m": {"wfs": {"model": "physical"}}}})
    spec = resolve_study(physical, validate_study(physical)).cases["ltao_sodium_D39m"].calibration.spec
    assert 4e9 < calibration_memory_bytes(spec) < 10e9
    default = view.cases["ltao_r0_13.5cm"].calibration.spec
    assert calibration_memory_bytes(default) == 1.5e9  # what small sensors declared before


def test_the_overlay_moves_no_key_of_the_telescope_study():
    """Over config/diameter.yaml, config/elt.yaml leaves every case of it as it was, and its own
    cases are those it runs alone: the same screens, slopes and lucky settings (the published
    39 m points are what config/elt.yaml alone gives)."""
    diameter = (CONFIG / "config.yaml", CONFIG / "diameter.yaml")
    before = resolve_study(*(lambda c: (c, validate_study(c)))(load_study(*diameter)[0]))
    after = resolve_study(*(lambda c: (c, validate_study(c)))(load_study(*diameter, CONFIG / "elt.yaml")[0]))
    alone = resolve_study(*(lambda c: (c, validate_study(c)))(load_study(*ELT)[0]))
    assert set(after.cases) - set(before.cases) == set(CASES)
    for name, case in [*before.cases.items(), *((n, alone.cases[n]) for n in CASES)]:
        assert after.cases[name].config_sha256 == case.config_sha256, name
        assert after.cases[name].screens.key == case.screens.key, name
        assert sha256(after.cases[name].lucky_settings) == sha256(case.lucky_settings), name
    assert after.cases["ltao_sodium_D39m"].slopes.key == alone.cases["ltao_sodium_D39m"].slopes.key


def test_composed_over_the_telescope_study_the_diameter_figure_draws_39m():
    """Issue 42's points on the `diameter` figure itself: its cases_matching takes the overlay's
    cases, the six-beacon ring as its own series; alone, the telescope study's list is as it was."""
    from luckyao.figures import FIGURE_KINDS, FigureSettings

    from synthetic import lucky_dataset

    diameter = (CONFIG / "config.yaml", CONFIG / "diameter.yaml")
    alone = resolve_study(*(lambda c: (c, validate_study(c)))(load_study(*diameter)[0])).config
    both = resolve_study(*(lambda c: (c, validate_study(c)))(load_study(*diameter, CONFIG / "elt.yaml")[0]))
    drawn = both.config["figures"]["diameter"]["cases"]
    assert [c for c in drawn if c not in CASES] == alone["figures"]["diameter"]["cases"]
    assert set(drawn) - set(alone["figures"]["diameter"]["cases"]) == set(CASES)
    spec = both.config["figures"]["diameter"]
    settings = FigureSettings.from_dict({**spec, "case_configs": {c: both.configs[c] for c in drawn}})
    frames = np.random.default_rng(2).uniform(0, 0.3, 100)
    ds = FIGURE_KINDS["quality_vs_diameter"][0](settings, [lucky_dataset(0.2, 5, frame_strehl=frames)] * len(drawn))
    assert list(ds.diameter.values) == [2.5, 4.2, 8.2, 16.0, 39.0]
    assert ds.case.sel(series="LTAO, 6 LGS 90 km", diameter=39.0).item() == "ltao_sodium_D39m"
    assert ds.case.sel(series="no AO", diameter=39.0).item() == "noao_D39m"
    assert ds.case.sel(series="LTAO, LGS 90 km", diameter=39.0).item() == ""  # the ring is its own series


def test_a_dense_39m_case_is_refused_naming_the_iterative_method():
    config = deep_merge(
        read_study(CONFIG / "config.yaml"),
        {"cases": {"dense": {"duration_s": 1.0, "telescope": {"diameter_m": 39.0}, "ao": {"mode": "ltao"}}}},
    )
    with pytest.raises(ConfigError, match=r"reconstructor .* more than .*tomography.method: iterative"):
        checked_study(config, memory_bytes=23e9)


def test_bad_39m_values_are_refused_by_key(elt):
    config = read_study(*ELT)
    ring = deep_merge(config, {"cases": {"ltao_sodium_D39m": {"lgs": {"asterism_diameter_arcsec": 200.0}}}})
    with pytest.raises(ConfigError, match="field_radius_arcsec"):
        validate_study(ring)
    derived = deep_merge(config, {"cases": {"noao_D39m": {"telescope": {"obscuration_ratio": 0.28}}}})
    with pytest.raises(ConfigError, match=r"cases.noao_D39m.telescope.obscuration_m.*obscuration_ratio"):
        validate_study(derived)


def test_the_elt_figure_draws_the_39m_points(elt):
    """The `elt` figure (kind quality_vs_diameter): one diameter, the no-AO and the six-beacon
    LTAO series, each point its own case's values."""
    from luckyao.figures import FIGURE_KINDS, FigureSettings

    from synthetic import lucky_dataset

    config, cases = elt
    spec = config["figures"]["elt"]
    settings = FigureSettings.from_dict({**spec, "case_configs": {c: cases[c] for c in spec["cases"]}})
    frames = np.random.default_rng(1).uniform(0, 0.3, 100)
    datasets = [lucky_dataset(0.1 * (k + 1), 5, frame_strehl=frames) for k in range(len(spec["cases"]))]
    ds = FIGURE_KINDS["quality_vs_diameter"][0](settings, datasets)
    assert list(ds.diameter.values) == [39.0]
    assert list(ds.series.values) == ["no AO", "LTAO, 6 LGS 90 km"]
    assert ds.case.sel(series="LTAO, 6 LGS 90 km", diameter=39.0).item() == "ltao_sodium_D39m"
    assert ds.strehl.sel(series="no AO", diameter=39.0).values.ravel()[0] == pytest.approx(0.1)
