"""The selection_power figure (issue 43 item 4): the share of the oracle's lucky gain each
criterion recovers, with paired time-block errors, from whatever criteria lucky.nc holds."""

import numpy as np
import pytest
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from test_figure_style import assert_told_apart, legend_styles

from luckyao.figures import FIGURE_KINDS, FigureSettings
from luckyao.figures.selection import ratio_with_error
from luckyao.lucky.accumulation import block_error
from luckyao.studyspec.schema import ConfigError, deep_merge
from luckyao.studyspec.study import load_study, validate_study

CRITERIA = ["strehl", "d50", "lgs_rms", "lgs_residual_rms", "true_rms", "lgs_spot_width"]
"""The last a criterion the figure has never heard of: it is drawn as any other."""
FRACTIONS = [0.01, 0.1, 1.0]


def lucky(strehl: np.ndarray, blocks: np.ndarray) -> xr.Dataset:
    """A lucky dataset of one target and the noiseless detector: ``strehl`` (criterion, fraction)
    and its time blocks' (block, criterion, fraction)."""
    return xr.Dataset(
        {
            "strehl": (("target", "criterion", "fraction", "detector"), strehl[None, :, :, None]),
            "strehl_block": (("block", "target", "criterion", "fraction", "detector"), blocks[:, None, :, :, None]),
            "mean_r0_500nm_m": 0.135,
        },
        coords={"criterion": CRITERIA, "fraction": FRACTIONS, "detector": ["noiseless"]},
    )


def made_up(seed: int, shared_sd: float = 0.02, n_blocks: int = 10) -> xr.Dataset:
    """Strehls whose blocks scatter about the run's, by ``shared_sd`` alike for every criterion
    and fraction (paired) and by 0.003 each; every fraction 1 the same (all frames)."""
    rng = np.random.default_rng(seed)
    strehl = np.empty((len(CRITERIA), len(FRACTIONS)))
    strehl[:, 2] = 0.10
    strehl[:, :2] = 0.10 + rng.uniform(0.0, 0.15, (len(CRITERIA), 2))
    strehl[CRITERIA.index("true_rms"), :2] = [0.24, 0.18]
    shared = rng.normal(0, 1, (n_blocks, 1, 1))
    blocks = strehl[None] + rng.normal(0, 0.003, (n_blocks, len(CRITERIA), len(FRACTIONS)))
    blocks[:, :, 2] = blocks[:, :1, 2]  # all frames: one image whatever the criterion
    return lucky(strehl, blocks + shared_sd * shared)


def settings(cases: list[str]) -> FigureSettings:
    config, resolved = load_study("config/config.yaml")
    return FigureSettings.from_dict(
        {
            "kind": "selection_power",
            "cases": cases,
            "fractions": [0.01, 0.1],
            "case_configs": {name: resolved[name] for name in cases},
        }
    )


def test_ratio_error_is_the_delta_method():
    """Blocks whose numerator is R times their denominator carry no error in R; with a constant
    denominator the error is the numerator's over it; both against block_error, the one home."""
    d = np.array([0.10, 0.14, 0.12, 0.09, 0.15])
    ratio, error = ratio_with_error(0.06, 0.12, 0.5 * d, d)
    assert ratio == 0.5 and error == pytest.approx(0.0, abs=1e-15)
    n = np.array([0.05, 0.07, 0.06, 0.04, 0.08])
    ratio, error = ratio_with_error(0.06, 0.12, n, np.full(5, 0.12))
    assert error == pytest.approx(float(block_error(n)) / 0.12, rel=1e-12)
    assert np.isnan(ratio_with_error(0.06, 0.12, np.empty(0), np.empty(0))[1])


def test_each_criterion_s_share_of_the_oracle_s_gain():
    datasets = [made_up(1), made_up(2)]
    figure = settings(["ltao_r0_13.5cm", "glao_r0_13.5cm"])
    make_data, draw = FIGURE_KINDS["selection_power"]
    ds = make_data(figure, datasets)
    assert list(ds.criterion.values) == [c for c in CRITERIA if c != "true_rms"]  # the unknown one too
    for i, lucky_ds in enumerate(datasets):
        s = lucky_ds.strehl.isel(target=0, detector=0)
        b = lucky_ds.strehl_block.isel(target=0, detector=0)
        for fraction in (0.01, 0.1):
            oracle_gain = float(
                s.sel(criterion="true_rms", fraction=fraction) - s.sel(criterion="true_rms", fraction=1.0)
            )
            assert float(ds.oracle_gain.isel(case=i).sel(fraction=fraction)) == pytest.approx(oracle_gain)
            for criterion in ds.criterion.values:
                gain = float(s.sel(criterion=criterion, fraction=fraction) - s.sel(criterion=criterion, fraction=1.0))
                row = ds.isel(case=i).sel(criterion=criterion, fraction=fraction)
                assert float(row.recovered) == pytest.approx(gain / oracle_gain)
                paired = block_error(
                    (b.sel(criterion=criterion, fraction=fraction) - b.sel(criterion=criterion, fraction=1.0)).values
                )
                assert float(row.gain_error) == pytest.approx(float(paired))
                assert 0 < float(row.recovered_error) < 0.5
    # paired: ten times the blocks' shared scatter leaves every error as it was
    louder = make_data(figure, [made_up(1, shared_sd=0.2), made_up(2, shared_sd=0.2)])
    for name in ("gain_error", "recovered_error", "oracle_gain_error"):
        np.testing.assert_allclose(louder[name], ds[name], rtol=1e-9)
    assert float(louder.strehl_all_error[0]) > 5 * float(ds.strehl_all_error[0])  # unpaired: grows
    fig = draw(ds, "selection_power")
    FigureCanvasAgg(fig).draw()
    assert_told_apart(legend_styles(fig))
    markers = [marker for _, (_, _, marker) in legend_styles(fig).items()]
    assert len(set(markers[: len(ds.criterion)])) == len(ds.criterion)


def test_the_oracle_is_required():
    ds = made_up(1).sel(criterion=[c for c in CRITERIA if c != "true_rms"])
    with pytest.raises(ValueError, match="no oracle"):
        FIGURE_KINDS["selection_power"][0](settings(["noao_r0_13.5cm"]), [ds])


def test_the_config_is_checked_before_any_job():
    """A case without AO (no oracle), a missing fractions key, or lucky.fractions without 1
    (S_all) are refused, naming the key."""
    config, _ = load_study("config/config.yaml")
    figure = {"kind": "selection_power", "cases": ["ltao_r0_13.5cm", "noao_r0_13.5cm"], "fractions": [0.01]}
    with pytest.raises(ConfigError, match=r"figures.power.cases': case 'noao_r0_13.5cm' has no oracle"):
        validate_study(deep_merge(config, {"figures": {"power": figure}}))
    with pytest.raises(ConfigError, match=r"figures.power.fractions': required"):
        validate_study(
            deep_merge(config, {"figures": {"power": {"kind": "selection_power", "cases": ["ltao_r0_13.5cm"]}}})
        )
    ok = dict(figure, cases=["ltao_r0_13.5cm"])
    no_all = deep_merge(config, {"figures": {"power": ok}, "lucky": {"fractions": [0.01, 0.1]}})
    no_all["figures"] = {"power": ok}  # the default figures' fractions are no longer all in lucky.fractions
    with pytest.raises(ConfigError, match=r"lucky.fractions': the selection_power figure 'power' needs 1.0"):
        validate_study(no_all)
    validate_study(deep_merge(config, {"figures": {"power": ok}}))


def test_the_selection_overlay_is_valid():
    """config/selection.yaml over config/config.yaml: its six AO cases with the residual budget,
    the intermittent two with their layer variability, the figures drawable."""
    config, cases = load_study("config/config.yaml", "config/selection.yaml")
    drawn = config["figures"]["selection_power"]["cases"]
    assert len(drawn) == 6 and all(cases[c]["ao"]["residual_budget"] for c in drawn)
    assert sum("layer_variability" in cases[c]["atmosphere"] for c in drawn) == 2
    assert config["figures"]["residual_budget"]["cases"] == drawn
