"""One look for every figure of the study: a palette whose first colours stay apart to
colour-blind eyes (``colour_vision``), one colour per main distinction of a figure, line
styles and markers for the second, a size that fits one screen, the fraction axis in
percent, and human names of metrics, criteria and config keys."""

from dataclasses import dataclass

import numpy as np
import xarray as xr
from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatter

PALETTE = ("#004488", "#E69F00", "#000000", "#BB5566", "#CC3311", "#228833", "#882255", "#4477AA")
"""Dark blue, orange, black, rose (Tol's high-contrast scheme with Okabe & Ito's orange), then
red, green, wine, blue (Tol's "vibrant", "bright" and "muted"): the first
:data:`DISTINCT_COLOURS` pairwise at least ``colour_vision.DISTINCT_DE00`` apart (CIEDE2000)
to normal, deuteranope and protanope eyes (no five colours are: 21 at most among these
schemes' and Okabe & Ito's); two series of a figure drawn in other colours differ in
marker or line style too (tests/test_figure_style.py checks every published figure)."""
DISTINCT_COLOURS = 4

LINE_STYLES = ("-", "--", "-.", ":")
MARKERS = "os^vDP<>"
AO_STYLE = {"ltao": "-", "glao": "-.", "none": "--"}
"""Line style of a case by its AO mode (the figures whose colour is the case)."""

SCREEN_INCHES = (12.8, 8.0)
"""The largest figure: 1920 x 1200 pixels at the saved :data:`DPI`, one screen."""
DPI = 150


@dataclass(frozen=True)
class Parameter:
    """How a config key reads on an axis: a name, its unit, and the factor from the
    config's unit to it."""

    name: str
    unit: str = ""
    scale: float = 1.0

    def label(self) -> str:
        return f"{self.name} [{self.unit}]" if self.unit else self.name


PARAMETERS = {
    "atmosphere.r0_500nm_m": Parameter("r0 at 500 nm", "cm", 100.0),
    "atmosphere.r0_amplitude_m": Parameter("r0 amplitude", "cm", 100.0),
    "telescope.diameter_m": Parameter("telescope diameter", "m"),
    "ao.mode": Parameter("AO"),
    "ao.n_actuators": Parameter("DM actuators across"),
    "wfs.n_subapertures": Parameter("WFS sub-apertures across"),
    "lgs.height_m": Parameter("LGS height", "km", 1e-3),
    "ao.apodisation.blocked_fraction": Parameter("pupil blocked by the apodisation", "%", 100.0),
    "ao.apodisation.driver": Parameter("apodisation driver"),
}
"""Config keys (sweep parameters) as figures name them; any other key reads as itself."""


def parameter(key: str) -> Parameter:
    """How ``key`` reads on an axis (:data:`PARAMETERS`, else the key itself)."""
    return PARAMETERS.get(key, Parameter(key))


def fraction_axis(ax) -> None:
    """The fraction of frames selected on a log x axis in percent, ticks read 1, 10, 100 (and
    20, 30, 40... on an axis short of a decade)."""
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(LogFormatter())
    ax.xaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    ax.set_xlabel("frames selected [%]")


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
    "lgs_high_order_rms": "LGS rms beyond the DM's fit",
    "lgs_ground_rms": "LGS ground-layer rms",
    "lgs_altitude_rms": "LGS altitude-layer rms",
    "dm_change_rms": "DM change between exposures",
    "lgs_slope_rms": "LGS slope rms",
    "learned": "learned (ridge on the laser criteria)",
}


def colour(k: int) -> str:
    """The k-th colour of the study's palette (cycling after eight)."""
    return PALETTE[k % len(PALETTE)]


def new_figure(width: float, height: float) -> Figure:
    """A figure with constrained layout, without pyplot (no GUI backend is touched), at most
    one screen (:data:`SCREEN_INCHES`)."""
    return Figure(figsize=(min(width, SCREEN_INCHES[0]), min(height, SCREEN_INCHES[1])), layout="constrained")


def band(ax, x, values: xr.Dataset, metric: str, shade: str) -> None:
    """Shade +-1 standard error around a curve, when the figure's data has it."""
    if f"{metric}_error" in values:
        value, error = values[metric].values, values[f"{metric}_error"].values
        ax.fill_between(np.asarray(x), value - error, value + error, color=shade, alpha=0.18, lw=0)


def with_error(datasets, metric: str) -> list[str]:
    """``metric`` and, when every case's lucky dataset has it, its Monte-Carlo error."""
    return [metric] + ([f"{metric}_error"] if all(f"{metric}_error" in ds for ds in datasets) else [])


def limit_flags(datasets, metric: str) -> list[str]:
    """The flags of ``metric`` every case's lucky dataset has: beyond the diffraction limit, and a
    d50 set by the field (:func:`luckyao.lucky.limits.add_limit_flags`)."""
    names = [f"{metric}_beyond_diffraction_limit", f"{metric}_field_bound"]
    return [name for name in names if all(name in ds for ds in datasets)]


FLAG_SUFFIXES = ("_noise_dominated", "_beyond_diffraction_limit", "_field_bound")
"""The flags that mask a value in a drawing: noise-dominated, beyond the diffraction limit, a d50
set by the field (:mod:`luckyao.lucky.dataset`, :mod:`luckyao.lucky.limits`)."""


def unflagged(values: xr.Dataset, name: str) -> np.ndarray:
    """``values[name]`` as float, NaN where any of its flags (:data:`FLAG_SUFFIXES`) is set: what
    a drawing shows."""
    y = np.array(values[name].values, dtype=float)
    for suffix in FLAG_SUFFIXES:
        if f"{name}{suffix}" in values:
            y = np.where(values[f"{name}{suffix}"].values.astype(bool), np.nan, y)
    return y


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
