"""The quality_vs_diameter figure: its cases grouped by series and diameter, and the
probability of a lucky frame with its time-block error, from synthetic lucky datasets."""

from pathlib import Path

import numpy as np
import pytest

from luckyao.figures import FIGURE_KINDS, FigureSettings
from luckyao.studyspec.study import load_study, validate_study
from luckyao.studyspec.sweeps import expand_study

from synthetic import lucky_dataset

CONFIG = Path(__file__).resolve().parents[1] / "config"
DIAMETER_FULL = (CONFIG / "config.yaml", CONFIG / "diameter.yaml", CONFIG / "diameter_full.yaml")
"""The telescope study with every series at every size (diameter_full: the 16 m scaled asterism too)."""
N_FRAMES, N_BLOCKS = 100, 5


@pytest.fixture(scope="module")
def figure():
    config, _ = load_study(*DIAMETER_FULL)
    cases = validate_study(config)
    spec = expand_study(config)["figures"]["diameter"]  # its cases_matching filled in
    settings = FigureSettings.from_dict({**spec, "case_configs": {c: cases[c] for c in spec["cases"]}})
    rng = np.random.default_rng(1)
    frames = [rng.uniform(0, 0.3, N_FRAMES) for _ in spec["cases"]]
    datasets = [lucky_dataset(k / 10, N_BLOCKS, frame_strehl=f) for k, f in enumerate(frames)]
    make_data, draw = FIGURE_KINDS["quality_vs_diameter"]
    return spec, frames, make_data(settings, datasets), draw


def test_cases_fall_into_series_by_ao_and_beacons(figure):
    spec, _, ds, _ = figure
    assert list(ds.diameter.values) == [2.5, 4.2, 8.2, 16.0]
    assert list(ds.series.values) == [
        "no AO",
        "LTAO, LGS 22 km",
        "LTAO, LGS 90 km",
        "LTAO, LGS 90 km, asterism x D",
    ]
    assert ds.case.sel(series="LTAO, LGS 90 km", diameter=4.2).item() == "ltao_sodium_D4.2m"
    assert ds.case.sel(series="LTAO, LGS 90 km, asterism x D", diameter=16.0).item() == "ltao_sodium_scaled_D16m"
    assert ds.case.sel(series="LTAO, LGS 90 km, asterism x D", diameter=4.2).item() == ""  # none there
    assert ds.case.sel(series="no AO", diameter=8.2).item() == "noao_D8.2m"
    # each point carries its own case's values (case k has Strehl k / 10)
    for k, case in enumerate(spec["cases"]):
        where = np.argwhere(ds.case.values == case)[0]
        assert ds.strehl.values[where[0], where[1], 0, 0] == pytest.approx(k / 10)


def test_lucky_frame_probability_and_its_wilson_interval(figure):
    """The fraction of frames above each threshold, inside its Wilson interval at the frames'
    effective sample size; the frames selected at each fraction carried along."""
    spec, frames, ds, _ = figure
    k = spec["cases"].index("ltao_D8.2m")
    for threshold in (0.1, 0.2):
        lucky = frames[k] > threshold
        cell = ds.sel(series="LTAO, LGS 22 km", diameter=8.2, threshold=threshold)
        assert cell.lucky_probability.item() == pytest.approx(lucky.mean())
        assert cell.lucky_probability_low.item() < lucky.mean() < cell.lucky_probability_high.item()
        assert cell.lucky_probability_frames.item() == N_FRAMES
        assert 1 <= cell.lucky_probability_frames_effective.item() <= N_FRAMES
    assert list(ds.n_frames_selected.sel(series="no AO", diameter=2.5).values) == [
        max(1, round(f * N_FRAMES)) for f in spec["fractions"]
    ]


def test_a_probability_of_no_lucky_frame_has_a_nonzero_interval(figure):
    """Frames uniform in [0, 0.3]: none above 0.5; the interval still reaches up."""
    spec, frames, ds, _ = figure
    config, _ = load_study(*DIAMETER_FULL)
    cases = validate_study(config)
    settings = FigureSettings.from_dict(
        {**spec, "strehl_thresholds": [0.5], "case_configs": {c: cases[c] for c in spec["cases"]}}
    )
    datasets = [lucky_dataset(0.1, N_BLOCKS, frame_strehl=f) for f in frames]
    ds = FIGURE_KINDS["quality_vs_diameter"][0](settings, datasets)
    assert (ds.lucky_probability.values[np.isfinite(ds.lucky_probability.values)] == 0).all()
    high = ds.lucky_probability_high.values[np.isfinite(ds.lucky_probability_high.values)]
    assert (high > 0).all() and (high < 0.05).all()


def test_series_labels_name_a_series_by_case():
    config, _ = load_study(*DIAMETER_FULL)
    cases = validate_study(config)
    names = ["ltao_r0_13.5cm", "ltao_r0_15cm"]  # both LTAO, 22 km, 4.2 m: apart only as named series
    settings = FigureSettings.from_dict(
        {
            "kind": "quality_vs_diameter",
            "cases": names,
            "criteria": ["strehl"],
            "fractions": [0.1],
            "series_labels": {"ltao_r0_15cm": "LTAO, r0 15 cm"},
            "case_configs": {c: cases[c] for c in names},
        }
    )
    datasets = [lucky_dataset(0.1, N_BLOCKS, frame_strehl=np.zeros(N_FRAMES)) for _ in names]
    ds = FIGURE_KINDS["quality_vs_diameter"][0](settings, datasets)
    assert list(ds.series.values) == ["LTAO, LGS 22 km", "LTAO, r0 15 cm"]


def test_it_draws(figure):
    _, _, ds, draw = figure
    fig = draw(ds, "diameter")
    assert len(fig.axes) == 6


def test_two_cases_at_one_point_are_refused():
    config, _ = load_study(*DIAMETER_FULL)
    cases = validate_study(config)
    names = ["ltao_r0_13.5cm", "ltao_r0_15cm"]  # both LTAO, 22 km, 4.2 m
    settings = FigureSettings.from_dict(
        {
            "kind": "quality_vs_diameter",
            "cases": names,
            "criteria": ["strehl"],
            "fractions": [0.1],
            "case_configs": {c: cases[c] for c in names},
        }
    )
    datasets = [lucky_dataset(0.1, N_BLOCKS, frame_strehl=np.zeros(N_FRAMES)) for _ in names]
    with pytest.raises(ValueError, match="both LTAO, LGS 22 km at 4.2 m"):
        FIGURE_KINDS["quality_vs_diameter"][0](settings, datasets)
