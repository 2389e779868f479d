"""Selection power: the share of the oracle's lucky gain each selection criterion recovers.

For a case, a criterion ``c`` and a fraction kept, ``R = (S_c - S_all) / (S_oracle - S_all)``,
where ``S`` is the Strehl ratio of the integrated image of the kept frames, recentred (the
figure's detector, the first target, registration ``cog``), ``S_all`` that of every frame
(fraction 1) and the oracle the true corrected rms (``true_rms``): 0 is no better than chance,
1 the oracle's gain. Every criterion is scored on the same frames, so the numerator and the
denominator are paired: the Monte-Carlo error comes from the time blocks (each block selected on
its own, ``<metric>_block`` of the lucky dataset) by the delta method for a ratio of block
means, the blocks' ``(n_b - R~ d_b) / mean(d)`` (``n_b``, ``d_b`` the blocks' numerator and
denominator, ``R~`` the ratio of their means) put through :func:`luckyao.lucky.accumulation.block_error`.
Every criterion the lucky datasets hold is drawn (the image criteria too, which need the
target's photons; the others are the lasers' alone).
"""

import numpy as np
import xarray as xr

from ..lucky.accumulation import block_error
from .settings import FigureSettings, case_coords
from .style import CRITERIA, MARKERS, colour, new_figure

ORACLE = "true_rms"
"""The criterion whose gain is the yardstick: selection by the true corrected rms."""

ALL_FRAMES = 1.0
"""The fraction whose integrated image is every frame recentred (``S_all``)."""

AIM = 0.5
"""The share of the oracle's gain at 1 % a laser-only criterion should reach (issue 43)."""


ORACLE_MARKERS = "*XHd"
"""The oracle's gain, a marker per fraction: none of the criteria's (:data:`.style.MARKERS`)."""


def criterion_marker(index: int) -> str:
    """The marker of the ``index``-th criterion: with more criteria than markers, the second
    round shifted by one, so that no two criteria share both colour and marker."""
    return MARKERS[(index + index // len(MARKERS)) % len(MARKERS)]


def ratio_with_error(numerator: float, denominator: float, numerator_blocks, denominator_blocks):
    """``numerator / denominator`` and its Monte-Carlo standard error from paired time blocks
    (delta method for a ratio of block means: :func:`block_error` of the linearised blocks);
    NaN error without blocks."""
    ratio = numerator / denominator
    n_b, d_b = np.asarray(numerator_blocks, dtype=float), np.asarray(denominator_blocks, dtype=float)
    if len(n_b) < 2:
        return ratio, np.nan
    block_ratio = n_b.mean() / d_b.mean()
    return ratio, float(block_error((n_b - block_ratio * d_b) / d_b.mean()))


def selection_criteria(datasets) -> list[str]:
    """Every criterion of the cases' lucky datasets but the oracle, in the datasets' order."""
    names = dict.fromkeys(str(c) for ds in datasets for c in ds.criterion.values)
    return [name for name in names if name != ORACLE]


def selection_power_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per case, criterion (every one the lucky datasets hold but the oracle; NaN where a case has
    not it) and fraction (the figure's): ``recovered`` and its paired error, the gain
    ``S_c - S_all`` and its paired error; per case and fraction the oracle's gain; per case
    ``S_all``."""
    criteria, fractions = selection_criteria(datasets), list(settings.fractions)
    shape = (len(datasets), len(criteria), len(fractions))
    recovered, recovered_error = np.full(shape, np.nan), np.full(shape, np.nan)
    gain, gain_error = np.full(shape, np.nan), np.full(shape, np.nan)
    oracle_gain, oracle_gain_error = np.full(shape[::2], np.nan), np.full(shape[::2], np.nan)
    strehl_all, strehl_all_error = np.full(len(datasets), np.nan), np.full(len(datasets), np.nan)
    for i, (name, ds) in enumerate(zip(settings.cases, datasets)):
        if ORACLE not in ds.criterion.values:
            raise ValueError(f"selection_power figure: case {name} has no oracle ({ORACLE}: cases with AO)")
        ds = ds.isel(target=0).sel(detector=settings.detector)
        has_blocks = "strehl_block" in ds

        def at(criterion, fraction):
            """The run's Strehl of ``criterion`` at ``fraction``, and its blocks' (none without)."""
            where = {"criterion": criterion, "fraction": fraction}
            blocks = ds["strehl_block"].sel(where).values if has_blocks else np.empty(0)
            return float(ds["strehl"].sel(where)), blocks

        every, every_blocks = at(ORACLE, ALL_FRAMES)
        strehl_all[i] = every
        strehl_all_error[i] = block_error(every_blocks) if has_blocks else np.nan
        for f, fraction in enumerate(fractions):
            oracle, oracle_blocks = at(ORACLE, fraction)
            oracle_gain[i, f] = oracle - every
            oracle_gain_error[i, f] = block_error(oracle_blocks - every_blocks) if has_blocks else np.nan
            for c, criterion in enumerate(criteria):
                if criterion not in ds.criterion.values:
                    continue
                value, value_blocks = at(criterion, fraction)
                gain[i, c, f] = value - every
                gain_error[i, c, f] = block_error(value_blocks - every_blocks) if has_blocks else np.nan
                recovered[i, c, f], recovered_error[i, c, f] = ratio_with_error(
                    value - every,
                    oracle - every,
                    value_blocks - every_blocks,
                    oracle_blocks - every_blocks,
                )
    dims = ("case", "criterion", "fraction")
    recovered_name = (
        "share of the oracle's (true rms selection's) lucky gain recovered, (S_c - S_all) / (S_oracle - S_all)"
    )
    paired = "paired Monte-Carlo standard error (time blocks)"
    return xr.Dataset(
        {
            "recovered": (dims, recovered, {"units": "1", "long_name": recovered_name}),
            "recovered_error": (dims, recovered_error, {"units": "1", "long_name": f"{paired}, delta method"}),
            "gain": (dims, gain, {"units": "1", "long_name": "Strehl ratio gained over all frames, S_c - S_all"}),
            "gain_error": (dims, gain_error, {"units": "1", "long_name": paired}),
            "oracle_gain": (
                ("case", "fraction"),
                oracle_gain,
                {"units": "1", "long_name": "Strehl ratio gained over all frames by the oracle, S_oracle - S_all"},
            ),
            "oracle_gain_error": (("case", "fraction"), oracle_gain_error, {"units": "1", "long_name": paired}),
            "strehl_all": (
                ("case",),
                strehl_all,
                {"units": "1", "long_name": "Strehl ratio of every frame recentred, S_all"},
            ),
            "strehl_all_error": (
                ("case",),
                strehl_all_error,
                {"units": "1", "long_name": "Monte-Carlo standard error of S_all (time blocks)"},
            ),
        },
        coords={
            **case_coords(settings, datasets),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames kept"}),
        },
        attrs={"detector": settings.detector, "oracle": ORACLE},
    )


def draw_selection_power(ds: xr.Dataset, title: str):
    """A panel per fraction: each criterion's share of the oracle's gain per case (marker and
    colour per criterion, ±1 paired standard error); the last panel: the oracle's gain."""
    n_cases, n_crit, n_frac = ds.sizes["case"], ds.sizes["criterion"], ds.sizes["fraction"]
    fig = new_figure(5.0 * (n_frac + 1), 5.0)
    axes = fig.subplots(1, n_frac + 1, squeeze=False)[0]
    x = np.arange(n_cases)
    labels = [str(label) for label in ds.label.values]
    width = 0.7 / max(n_crit, 1)
    for f, ax in enumerate(axes[:n_frac]):
        for c, criterion in enumerate(ds.criterion.values):
            row = ds.isel(criterion=c, fraction=f)
            offset = x + (c - (n_crit - 1) / 2) * width
            shade, marker = colour(c), criterion_marker(c)
            ax.errorbar(offset, row.recovered, yerr=row.recovered_error, fmt="none", ecolor=shade, elinewidth=1)
            ax.plot(
                offset, row.recovered, ls="none", marker=marker, color=shade, label=CRITERIA.get(criterion, criterion)
            )
        ax.axhline(0.0, color="k", lw=0.8)
        ax.axhline(1.0, color="k", lw=0.8, ls="--")
        ax.axhline(AIM, color="0.5", lw=0.8, ls=":")
        ax.set_title(f"({chr(97 + f)}) {100 * float(ds.fraction[f]):g} % of frames kept", loc="left", fontsize=9)
        ax.set_ylabel("share of the oracle's gain recovered")
        ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
        ax.grid(alpha=0.3, axis="y")
    ax = axes[n_frac]
    for f in range(n_frac):
        row = ds.isel(fraction=f)
        offset = x + (f - (n_frac - 1) / 2) * 0.2
        ax.errorbar(offset, row.oracle_gain, yerr=row.oracle_gain_error, fmt="none", ecolor="k", elinewidth=1)
        ax.plot(
            offset,
            row.oracle_gain,
            ls="none",
            marker=ORACLE_MARKERS[f % len(ORACLE_MARKERS)],
            color="k",
            label=f"oracle, {100 * float(ds.fraction[f]):g} %",
        )
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_title(f"({chr(97 + n_frac)}) the oracle's gain, S_oracle - S_all", loc="left", fontsize=9)
    ax.set_ylabel("Strehl ratio gained over all frames")
    ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=min(n_crit, 6),
        fontsize=8,
        title="selection criterion (bars: ±1 paired standard error, time blocks); dashed: the oracle, "
        f"dotted: {AIM:g} of its gain, 0: all frames",
        title_fontsize=8,
    )
    fig.suptitle(
        f"{title}: share of the oracle's lucky gain each criterion recovers ({ds.attrs['detector']} detector, "
        "first target, recentred Strehl ratio)"
    )
    return fig
