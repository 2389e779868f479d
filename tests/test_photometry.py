"""The photometric scale (``luckyao.photometry``): photons per frame of a star of a given
magnitude, against a hand calculation from Vega's I-band flux density."""

import numpy as np
import pytest

from luckyao.photometry import (
    Photometry,
    case_aperture,
    collecting_area_m2,
    config_with_defaults,
    magnitude_of,
    photons_of,
)
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import read_study, validate_study
from luckyao.studyspec.sweeps import expand_study
from luckyao.studyspec.view import resolve_study


def test_photons_at_zero_magnitude_are_the_hand_calculation_from_vega():
    """Vega's I-band flux density, 112.6e-11 erg s^-1 cm^-2 A^-1 (Bessell, Castelli & Plez 1998,
    table A2), is 1.126e-8 W m^-2 um^-1 (1 erg s^-1 cm^-2 A^-1 = 1e-7 W / (1e-4 m^2 1e-4 um) =
    10 W m^-2 um^-1): the config's 1.13e-8. By hand, for the 4.2 m telescope (1.2 m obscuration,
    A = pi/4 (17.64 - 1.44) = 12.7235 m^2), a 0.3 um band, throughput 0.5 and 10 ms frames: P =
    1.13e-8 x 0.3 x 12.7235 x 0.5 = 2.1566e-8 W, an 0.8 um photon carries h c / lambda =
    2.4831e-19 J, so 8.6853e10 photons a second, 8.685e8 a frame; I = 15 gives 868.5 of them,
    I = 18 54.8."""
    assert 112.6e-11 * 1e-7 / (1e-4 * 1e-4) == pytest.approx(1.126e-8)
    scale = Photometry.from_config()
    area = collecting_area_m2(4.2, 1.2)
    assert area == pytest.approx(12.7235, abs=1e-4)
    n0 = scale.photons_at_zero_magnitude(area, 0.01)
    assert n0 == pytest.approx(8.6853e8, rel=2e-4)
    assert float(scale.photons_per_frame(15.0, area, 0.01)) == pytest.approx(868.5, rel=2e-4)
    assert float(scale.photons_per_frame(18.0, area, 0.01)) == pytest.approx(54.80, rel=2e-3)
    assert float(scale.magnitude(scale.photons_per_frame(16.3, area, 0.01), area, 0.01)) == pytest.approx(16.3)
    # what the published figures used (figures/paper/registration.nc's i_zero_photons_per_frame), bit for bit
    assert n0 == 868536057.6475518


def test_photons_scale_with_aperture_frame_time_and_band():
    """The same star gives photons in proportion to the collecting area, the frame time, the
    band's width, its zero point and the throughput; one magnitude is a factor 10^0.4."""
    scale = Photometry.from_config()
    base = scale.photons_at_zero_magnitude(collecting_area_m2(4.2, 1.2), 0.01)
    area_8m = collecting_area_m2(8.2, 2.286)
    assert scale.photons_at_zero_magnitude(area_8m, 0.01) / base == pytest.approx(
        (8.2**2 - 2.286**2) / (4.2**2 - 1.2**2)
    )
    assert scale.photons_at_zero_magnitude(collecting_area_m2(4.2, 1.2), 0.02) == pytest.approx(2 * base)
    narrow = Photometry.from_config({"bandwidth_um": 0.15, "throughput": 0.25})
    assert narrow.photons_at_zero_magnitude(collecting_area_m2(4.2, 1.2), 0.01) == pytest.approx(base / 4)
    assert float(photons_of(1.0, base) / photons_of(0.0, base)) == pytest.approx(10**-0.4)
    assert float(magnitude_of(base / 100, base)) == pytest.approx(5.0)


def test_the_papers_two_conversions_disagree_and_the_scale_sits_by_the_first():
    """The source paper: 1,000 photons per frame is I = 15 and 100 is I = 18. They imply
    magnitude-0 fluxes of 1.0e9 and 1.58e9 photons per frame, half a magnitude apart; this scale
    (8.69e8) puts 1,000 photons at I = 14.85 (0.15 mag from the first) and 100 at I = 17.35
    (0.65 mag from the second)."""
    n0 = Photometry.from_config().photons_at_zero_magnitude(collecting_area_m2(4.2, 1.2), 0.01)
    first, second = photons_of(-15.0, 1000.0), photons_of(-18.0, 100.0)  # N_0 of each conversion
    assert float(first) == pytest.approx(1e9) and float(second) == pytest.approx(10**9.2)
    assert float(magnitude_of(first, second)) == pytest.approx(0.5)
    assert float(magnitude_of(1000.0, n0)) == pytest.approx(14.85, abs=0.005)
    assert float(magnitude_of(100.0, n0)) == pytest.approx(17.35, abs=0.005)
    assert 18 - float(magnitude_of(100.0, n0)) == pytest.approx(0.65, abs=0.005)


def test_the_scale_is_a_config_block_that_enters_no_case():
    """``photometry`` (a top-level block, its defaults the schema's) reaches the figures only: a
    study with another scale has the same cases, resolved configs, products and lucky settings;
    a key the schema does not know is refused, naming it."""
    assert config_with_defaults() == {
        "band": "I",
        "wavelength_um": 0.8,
        "zero_point_w_m2_um": 1.13e-8,
        "bandwidth_um": 0.3,
        "throughput": 0.5,
    }
    assert config_with_defaults({"throughput": 0.4})["throughput"] == 0.4
    with pytest.raises(ValueError, match="unknown keys"):
        config_with_defaults({"zeropoint": 1.0})
    study = expand_study(read_study("config/config.yaml"))
    other = dict(study, photometry={"band": "R", "wavelength_um": 0.65, "throughput": 0.3})
    views = [resolve_study(s, validate_study(s)) for s in (study, other)]
    for name, case in views[0].cases.items():
        twin = views[1].cases[name]
        assert case.config_sha256 == twin.config_sha256 and case.lucky_settings == twin.lucky_settings
        assert {k: p.key for k, p in case.products().items()} == {k: p.key for k, p in twin.products().items()}
    with pytest.raises(ConfigError, match="photometry"):
        validate_study(dict(study, photometry={"zeropoint": 1.0}))
    area, frame_time = case_aperture(views[0].cases["ltao_r0_13.5cm"].config)
    assert (area, frame_time) == (collecting_area_m2(4.2, 1.2), 0.01)
    assert np.isclose(area, np.pi / 4 * (4.2**2 - 1.2**2))
