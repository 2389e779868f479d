"""Telescope size: integrated-image quality and the probability of a lucky frame vs the diameter.

The cases of a ``quality_vs_diameter`` figure fall into series that differ only in their
telescope's size (and what the size derives, studyspec/scaling.py): a series per AO mode and
beacon height (``LTAO, LGS 22 km``), or as ``series_labels`` names it, a point per diameter.
The probability of a lucky frame is the fraction of frames whose short-exposure Strehl (the
detected frame's peak over the diffraction-limited peak) exceeds each threshold, with its
Wilson interval at the frames' effective sample size (:mod:`luckyao.lucky.proportions`):
never of zero width, also where no frame qualifies.
"""

import numpy as np
import xarray as xr

from ..lucky.proportions import Z_ONE_SIGMA, lucky_fraction
from .settings import FigureSettings
from .style import CRITERIA, LINE_STYLES, MARKERS, colour, new_figure, series_fraction_lines, with_error

SHOWN = {"strehl": "Strehl ratio", "d50_arcsec": "50% energy diameter [arcsec]"}
"""The integrated-image metrics drawn against the diameter (FWHM stays in the dataset)."""


def series_label(settings: FigureSettings, summary) -> str:
    """What a case's series is: as the figure's ``series_labels`` names it, else its AO mode
    and, with AO, its beacons' height."""
    named = dict(settings.series_labels)
    if summary.name in named:
        return named[summary.name]
    parts = summary.parts()
    return parts["ao"] if summary.ao_mode == "none" else f"{parts['ao']}, {parts['lgs']}"


def series_points(settings: FigureSettings) -> tuple[list[str], list[float], dict]:
    """The figure's series, its diameters, and ``{(series, diameter): case index}``; two cases
    at one point refused."""
    summaries = settings.summaries()
    diameters = [settings.case(name).telescope.diameter_m for name in settings.cases]
    labels = [series_label(settings, s) for s in summaries]
    where = {}
    for i, (label, diameter) in enumerate(zip(labels, diameters)):
        if (label, diameter) in where:
            raise ValueError(
                f"cases {settings.cases[where[label, diameter]]} and {settings.cases[i]}: both "
                f"{label} at {diameter:g} m"
            )
        where[label, diameter] = i
    return list(dict.fromkeys(labels)), sorted(set(diameters)), where


def _first_target(values: xr.DataArray) -> xr.DataArray:
    """The first target's values (the datasets arrive on the baseline registration,
    ``figures.baseline_registration``)."""
    return values.isel(target=0) if "target" in values.dims else values


def quality_vs_diameter_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality (first target) per series, diameter, criterion and fraction, the
    frames behind each fraction, and the probability of a lucky frame per series, diameter and
    Strehl threshold, with its interval."""
    series, x_values, where = series_points(settings)
    criteria, fractions = list(settings.criteria), list(settings.fractions)
    thresholds = list(settings.strehl_thresholds)
    shape = (len(series), len(x_values))
    data = {}
    for metric in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        for name in with_error(datasets, metric):
            table = np.full(shape + (len(criteria), len(fractions)), np.nan)
            for (label, diameter), i in where.items():
                table[series.index(label), x_values.index(diameter)] = _first_target(
                    datasets[i][name].sel(criterion=criteria, fraction=fractions, detector=settings.detector)
                ).values
            data[name] = (("series", "diameter", "criterion", "fraction"), table, dict(datasets[0][name].attrs))
    counts = np.full(shape + (len(fractions),), -1, dtype=np.int64)
    for (label, diameter), i in where.items():
        counts[series.index(label), x_values.index(diameter)] = _first_target(
            datasets[i].n_frames_selected.sel(fraction=fractions)
        )
    data["n_frames_selected"] = (
        ("series", "diameter", "fraction"),
        counts,
        {"units": "1", "long_name": "frames selected at each fraction (-1: no case at this point)"},
    )
    names = ("fraction", "low", "high", "n_effective", "n_frames")
    lucky = {name: np.full(shape + (len(thresholds),), np.nan) for name in names}
    for (label, diameter), i in where.items():
        frames = _first_target(datasets[i]["frame_strehl"].sel(detector=settings.detector))
        cell = series.index(label), x_values.index(diameter)
        for k, threshold in enumerate(thresholds):
            found = lucky_fraction(frames.values, threshold, datasets[i].sizes.get("block", 0))
            for name in names:
                lucky[name][cell + (k,)] = found[name]
    dims = ("series", "diameter", "threshold")
    interval = f"Wilson score interval ({Z_ONE_SIGMA:g} sigma, 68.3 %) at the effective sample size"
    data["lucky_probability"] = (
        dims,
        lucky["fraction"],
        {"units": "1", "long_name": "fraction of frames whose short-exposure Strehl exceeds the threshold"},
    )
    data["lucky_probability_low"] = (dims, lucky["low"], {"units": "1", "long_name": f"lower bound: {interval}"})
    data["lucky_probability_high"] = (dims, lucky["high"], {"units": "1", "long_name": f"upper bound: {interval}"})
    data["lucky_probability_frames_effective"] = (
        dims,
        lucky["n_effective"],
        {
            "units": "1",
            "long_name": "effective number of independent frames: frames over the variance inflation of "
            "the frame Strehl's mean (time blocks, batch means)",
        },
    )
    data["lucky_probability_frames"] = (dims, lucky["n_frames"], {"units": "1", "long_name": "frames counted"})
    cases = np.full(shape, "", dtype=object)
    for (label, diameter), i in where.items():
        cases[series.index(label), x_values.index(diameter)] = settings.cases[i]
    return xr.Dataset(
        data,
        coords={
            "series": ("series", series, {"long_name": "AO mode and beacon height"}),
            "diameter": ("diameter", x_values, {"units": "m", "long_name": "telescope diameter"}),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
            "threshold": ("threshold", thresholds, {"units": "1", "long_name": "short-exposure Strehl threshold"}),
            "case": (("series", "diameter"), cases.astype(str), {"long_name": "the case of each point ('' none)"}),
        },
        attrs={"detector": settings.detector},
    )


def _probability_bars(cell: xr.Dataset) -> list[np.ndarray]:
    """The lucky-frame probability's error bars below and above: its Wilson interval."""
    p = cell.lucky_probability.values
    return [p - cell.lucky_probability_low.values, cell.lucky_probability_high.values - p]


def draw_quality_vs_diameter(ds: xr.Dataset, title: str):
    """A row per criterion: Strehl and d50 vs diameter (a colour per series, a line style per
    fraction); a last column: the probability of a lucky frame (a line style per threshold)."""
    n_rows = ds.sizes["criterion"]
    fig = new_figure(14, 3.6 * n_rows + 1.2)
    axes = fig.subplots(n_rows, 3, squeeze=False)
    x = ds.diameter.values
    for r, criterion in enumerate(ds.criterion.values):
        for ax, (metric, name) in zip(axes[r], SHOWN.items()):
            series_fraction_lines(ax, x, ds.sel(criterion=criterion), metric)
            ax.set_xlabel("telescope diameter [m]")
            ax.set_ylabel(name)
            ax.grid(alpha=0.3)
        axes[r, 0].set_title(
            f"({chr(ord('a') + r)}) selection by {CRITERIA.get(criterion, criterion)}", loc="left", fontsize=10
        )
        axes[r, 2].set_visible(r == 0)
    ax = axes[0, 2]
    for s, series in enumerate(ds.series.values):
        for k, threshold in enumerate(ds.threshold.values):
            cell = ds.sel(series=series, threshold=threshold)
            p = cell.lucky_probability.values
            ax.errorbar(
                x,
                p,
                yerr=_probability_bars(cell),
                color=colour(s),
                ls=LINE_STYLES[k % 4],
                marker=MARKERS[k % 8],
                ms=4,
                capsize=2,
                lw=1.2,
                label=f"{series}, S > {threshold:g}",
            )
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_ylim(0, 1)
    ax.set_xlabel("telescope diameter [m]")
    ax.set_ylabel("fraction of frames")
    ax.set_title("probability of a lucky frame\n(short-exposure Strehl above a threshold)", loc="left", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=ds.sizes["fraction"],
        fontsize=8,
        title="colour: AO and beacons; line style and marker: fraction of frames selected\n"
        "error bars: ±1 Monte-Carlo standard error (time blocks); probability: Wilson 68 % interval",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image quality vs telescope diameter ({ds.attrs['detector']} detector)")
    return fig
