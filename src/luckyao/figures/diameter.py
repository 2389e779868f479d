"""Telescope size: integrated-image quality and the probability of a lucky frame vs the diameter.

The cases of a ``quality_vs_diameter`` figure fall into series that differ only in their
telescope's size (and what the size derives, studyspec/scaling.py): a series per AO mode and
beacon height (``LTAO, LGS 22 km``), a point per diameter. The probability of a lucky frame
is the fraction of frames whose short-exposure Strehl (the detected frame's peak over the
diffraction-limited peak) exceeds each threshold; its Monte-Carlo error comes from the
case's time blocks (batch means, as every other error of the study).
"""

import numpy as np
import xarray as xr

from ..lucky.accumulation import batch_mean_error
from .settings import FigureSettings
from .style import CRITERIA, LINE_STYLES, MARKERS, colour, new_figure, series_fraction_lines, with_error

SHOWN = {"strehl": "Strehl ratio", "d50_arcsec": "50% energy diameter [arcsec]"}
"""The integrated-image metrics drawn against the diameter (FWHM stays in the dataset)."""


def _series_label(summary) -> str:
    """What a case's series is: its AO mode and, with AO, its beacons' height."""
    parts = summary.parts()
    return parts["ao"] if summary.ao_mode == "none" else f"{parts['ao']}, {parts['lgs']}"


def lucky_frame_probability(frame_strehl: np.ndarray, threshold: float, n_blocks: int) -> tuple[float, float]:
    """Fraction of frames with short-exposure Strehl above ``threshold``, and its batch-means
    error over ``n_blocks`` time blocks (NaN with fewer than two)."""
    lucky = (np.asarray(frame_strehl) > threshold).astype(float)
    return float(lucky.mean()), batch_mean_error(lucky, n_blocks) if n_blocks >= 2 else np.nan


def quality_vs_diameter_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality (first target) per series, diameter, criterion and fraction, and
    the probability of a lucky frame per series, diameter and Strehl threshold, with errors."""
    summaries = settings.summaries()
    diameters = [settings.case(name).telescope.diameter_m for name in settings.cases]
    labels = [_series_label(s) for s in summaries]
    series, x_values = list(dict.fromkeys(labels)), sorted(set(diameters))
    where = {}
    for i, (label, diameter) in enumerate(zip(labels, diameters)):
        if (label, diameter) in where:
            raise ValueError(
                f"cases {settings.cases[where[label, diameter]]} and {settings.cases[i]}: both "
                f"{label} at {diameter:g} m"
            )
        where[label, diameter] = i
    criteria, fractions = list(settings.criteria), list(settings.fractions)
    thresholds = list(settings.strehl_thresholds)
    shape = (len(series), len(x_values))
    data = {}
    for metric in ("strehl", "fwhm_arcsec", "d50_arcsec"):
        for name in with_error(datasets, metric):
            table = np.full(shape + (len(criteria), len(fractions)), np.nan)
            for (label, diameter), i in where.items():
                table[series.index(label), x_values.index(diameter)] = (
                    datasets[i][name]
                    .sel(criterion=criteria, fraction=fractions, detector=settings.detector)
                    .isel(target=0)
                    .values
                )
            data[name] = (("series", "diameter", "criterion", "fraction"), table, dict(datasets[0][name].attrs))
    probability, error = np.full(shape + (len(thresholds),), np.nan), np.full(shape + (len(thresholds),), np.nan)
    for (label, diameter), i in where.items():
        frames = datasets[i]["frame_strehl"].sel(detector=settings.detector)
        frames = frames.isel(target=0) if "target" in frames.dims else frames
        cell = series.index(label), x_values.index(diameter)
        for k, threshold in enumerate(thresholds):
            probability[cell + (k,)], error[cell + (k,)] = lucky_frame_probability(
                frames.values, threshold, datasets[i].sizes.get("block", 0)
            )
    dims = ("series", "diameter", "threshold")
    data["lucky_probability"] = (
        dims,
        probability,
        {"units": "1", "long_name": "fraction of frames whose short-exposure Strehl exceeds the threshold"},
    )
    data["lucky_probability_error"] = (
        dims,
        error,
        {"units": "1", "long_name": "Monte-Carlo standard error of lucky_probability (time blocks, batch means)"},
    )
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
            ax.errorbar(
                x,
                cell.lucky_probability.values,
                yerr=cell.lucky_probability_error.values,
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
        "error bars: ±1 Monte-Carlo standard error (time blocks)",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image quality vs telescope diameter ({ds.attrs['detector']} detector)")
    return fig
