"""One look for every figure of the study: a colour-blind-safe palette (Okabe & Ito
2008, "Color Universal Design"), one colour per main distinction of a figure, line
styles for the second, and the names of metrics and criteria."""

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

PALETTE = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#F0E442", "#000000")
"""Okabe-Ito: blue, vermillion, bluish green, reddish purple, orange, sky blue, yellow, black."""

LINE_STYLES = ("-", "--", "-.", ":")
MARKERS = "os^vDP<>"
AO_STYLE = {"ltao": "-", "glao": "-.", "none": "--"}
"""Line style of a case by its AO mode (the figures whose colour is the case)."""

METRICS = {
    "strehl": "Strehl ratio",
    "fwhm_arcsec": "FWHM [arcsec]",
    "d50_arcsec": "50% energy diameter [arcsec]",
}
CRITERIA = {
    "strehl": "image Strehl",
    "d50": "50%-energy diameter",
    "lgs_rms": "LGS rms",
    "lgs_residual_rms": "LGS pseudo-closed-loop rms",
    "true_rms": "true rms (oracle)",
}


def colour(k: int) -> str:
    """The k-th colour of the study's palette (cycling after eight)."""
    return PALETTE[k % len(PALETTE)]


def new_figure(width: float, height: float) -> Figure:
    """A figure with constrained layout, without pyplot (no GUI backend is touched)."""
    return Figure(figsize=(width, height), layout="constrained")


def band(ax, x, values: xr.Dataset, metric: str, shade: str) -> None:
    """Shade +-1 standard error around a curve, when the figure's data has it."""
    if f"{metric}_error" in values:
        value, error = values[metric].values, values[f"{metric}_error"].values
        ax.fill_between(np.asarray(x), value - error, value + error, color=shade, alpha=0.18, lw=0)


def with_error(datasets, metric: str) -> list[str]:
    """``metric`` and, when every case's lucky dataset has it, its Monte-Carlo error."""
    return [metric] + ([f"{metric}_error"] if all(f"{metric}_error" in ds for ds in datasets) else [])


def series_fraction_lines(ax, x, ds, metric: str) -> None:
    """``ds[metric]`` (series, fraction) against ``x`` with its ``<metric>_error`` bars when
    present: a colour per series, a line style and marker per fraction."""
    for s, series in enumerate(ds.series.values):
        for k, fraction in enumerate(ds.fraction.values):
            cell = ds.sel(series=series, fraction=fraction)
            error = cell[f"{metric}_error"].values if f"{metric}_error" in cell else None
            ax.errorbar(
                x,
                cell[metric].values,
                yerr=error,
                color=colour(s),
                ls=LINE_STYLES[k % 4],
                marker=MARKERS[k % 8],
                ms=4,
                capsize=2,
                lw=1.2,
                label=f"{series}, {100 * fraction:g} %",
            )
