"""The standard outputs, without a study: the detectors' order, the noise-dominated flag,
units that UDUNITS (netCDF) and FITS parse. The study's own datasets and FITS files are
checked in test_workflow.py."""

import json

import astropy.units as u
import cf_units
import numpy as np
import pytest
import xarray as xr
from astropy.io import fits

from luckyao.io.fits import _hdu
from luckyao.io.hashing import canonical_json
from luckyao.lucky.dataset import NOISE_DOMINATED, add_noise_flags
from luckyao.studyspec.lucky import by_signal, lucky_settings
from luckyao.studyspec.schema import key_units
from luckyao.studyspec.study import load_study

from studies import REPO


def default_study() -> tuple[dict, dict]:
    """The default study's config and cases."""
    return load_study(REPO / "config" / "config.yaml")


def test_the_default_studys_detectors_are_ordered_by_signal_not_as_text():
    """A case's detectors reach its job as canonical JSON, keys sorted as text (``rn0.1_100ph``
    before ``rn0.1_10ph``); ``lucky.nc`` stores them by signal: the noiseless first, then by
    read noise and photons per frame (the tiny study's file: test_workflow.py)."""
    study, cases = default_study()
    detectors = json.loads(canonical_json(lucky_settings(study, cases, "ltao_r0_13.5cm")))["detectors"]
    assert list(detectors)[1:3] == ["rn0.1_100ph", "rn0.1_10ph"]  # the text order the job computes in
    order = by_signal(detectors)
    assert detectors[order[0]]["photons_per_frame"] is None
    keys = [(detectors[name]["read_noise_e"], detectors[name]["photons_per_frame"]) for name in order[1:]]
    assert keys == sorted(keys) and len(keys) == 10
    assert order[1:3] == ["rn0.1_10ph", "rn0.1_100ph"]


def test_by_signal_ties_go_by_name():
    detectors = {
        "b": {"photons_per_frame": 10.0, "read_noise_e": 1.0},
        "a": {"photons_per_frame": 10.0, "read_noise_e": 1.0},
        "clean": {"photons_per_frame": None, "read_noise_e": 0.0},
        "bright": {"photons_per_frame": 1e4, "read_noise_e": 0.0},
    }
    assert by_signal(detectors) == ["clean", "bright", "a", "b"]


def test_noise_flags_mark_values_far_from_their_noiseless_counterpart():
    """``<metric>_noise_dominated``: 1 where the value departs from the noiseless frames' by more
    than 30 % (a Strehl of 29.6 for 0.2, NaN), 0 within; none without the counterpart."""
    values = np.array([0.2, 0.25, 29.6, np.nan, 0.5])
    clean = np.array([0.2, 0.2, 0.2, 0.2, 0.5 / (1 - NOISE_DOMINATED / 2)])  # the last: 15 % off
    ds = xr.Dataset(
        {
            "strehl": ("detector", values, {"units": "1"}),
            "strehl_noiseless": ("detector", clean),
            "d50_arcsec": ("detector", values),
        }
    )
    add_noise_flags(ds)
    assert ds.strehl_noise_dominated.values.tolist() == [0, 0, 1, 1, 0]
    assert ds.strehl_noise_dominated.dtype == np.int8 and ds.strehl_noise_dominated.attrs["units"] == "1"
    assert "d50_arcsec_noise_dominated" not in ds


def test_fits_unit_parses_as_a_fits_unit():
    """``BUNIT`` of an image: astropy's FITS unit parser reads it (before: '1', refused)."""
    hdu = _hdu(fits, np.full((4, 4), 1 / 16, np.float32), "LUCKY", [])
    assert u.Unit(hdu.header["BUNIT"], format="fits") == u.dimensionless_unscaled


@pytest.mark.parametrize(
    "key, units",
    [("atmosphere.r0_500nm_m", "m"), ("atmosphere.wind_speed_m_s", "m s-1"), ("duration_s", "s"), ("ao.n", "1")],
)
def test_a_config_keys_units_come_from_its_name_and_parse_in_udunits(key, units):
    assert key_units(key) == units
    cf_units.Unit(units)


@pytest.mark.parametrize("units", ["photon", "electron", "pixel"])
def test_the_units_the_datasets_had_are_not_udunits(units):
    """Why a count is ``1`` in the datasets (what it counts in its long_name): UDUNITS refuses these."""
    with pytest.raises(ValueError):
        cf_units.Unit(units)
