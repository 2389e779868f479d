"""The apodisation figure (config/apodisation.yaml): a quality_vs_parameter figure over the
blocked fraction, a series per driver, and the flux lost with its time-block error, from
synthetic lucky datasets."""

from pathlib import Path

import numpy as np
import pytest

from luckyao.figures import FIGURE_KINDS, FigureSettings
from luckyao.studyspec.study import load_study, validate_study
from luckyao.studyspec.sweeps import expand_study, sweep_points

from synthetic import lucky_dataset

CONFIG = Path(__file__).resolve().parents[1] / "config"
N_FRAMES, N_BLOCKS = 100, 5


@pytest.fixture(scope="module")
def figure():
    config, _ = load_study(CONFIG / "config.yaml", CONFIG / "apodisation.yaml")
    cases = validate_study(config)
    spec = expand_study(config)["figures"]["apodisation"]
    points = [[p.case, p.values] for p in sweep_points(config, "apodisation")]
    settings = FigureSettings.from_dict(
        {**spec, "case_configs": {c: cases[c] for c in spec["cases"]}, "sweep_points": points}
    )
    rng = np.random.default_rng(2)
    fluxes = [1.0 - rng.uniform(0, p[1]["ao.apodisation.blocked_fraction"] * 1.5, N_FRAMES) for p in points]
    datasets = [lucky_dataset(k / 10, N_BLOCKS, transmitted_flux=f) for k, f in enumerate(fluxes)]
    make_data, draw = FIGURE_KINDS["quality_vs_parameter"]
    return points, cases, fluxes, make_data(settings, datasets), draw


def test_every_point_is_an_apodised_case_at_8_2_m(figure):
    points, cases, _, ds, _ = figure
    assert list(ds.x.values) == [0.0, 0.1, 0.2, 0.3]
    assert list(ds.series.values) == ["driver lgs", "driver oracle"]
    for case, values in points:
        config = cases[case]
        assert config["telescope"]["diameter_m"] == 8.2 and config["wfs"]["n_subapertures"] == 16
        assert config["ao"]["apodisation"] == {
            "driver": values["ao.apodisation.driver"],
            "blocked_fraction": values["ao.apodisation.blocked_fraction"],
        }


def test_flux_lost_and_its_block_error(figure):
    """1 - the mean transmitted flux, and the spread of its five block means over sqrt(5)."""
    points, _, fluxes, ds, _ = figure
    for (case, values), flux in zip(points, fluxes):
        cell = ds.sel(series=f"driver {values['ao.apodisation.driver']}", x=values["ao.apodisation.blocked_fraction"])
        lost = 1.0 - flux
        assert cell.flux_lost.item() == pytest.approx(lost.mean())
        blocks = lost.reshape(N_BLOCKS, -1).mean(axis=1)
        assert cell.flux_lost_error.item() == pytest.approx(blocks.std(ddof=1) / np.sqrt(N_BLOCKS))


def test_it_draws_the_flux_lost_beside_the_quality(figure):
    *_, ds, draw = figure
    fig = draw(ds, "apodisation")
    assert len([ax for ax in fig.axes if ax.get_visible()]) == 2 * 3 + 1
