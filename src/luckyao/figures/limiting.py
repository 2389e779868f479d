"""The limiting magnitude of a reference star against the telescope's diameter.

For each case of a ``limiting_magnitude`` figure (series and diameters as
``quality_vs_diameter``: :func:`.diameter.series_points`), the knees of the detector sweep
(:func:`.registration.knees`: the signal from which the integrated image keeps 90 % of its
noiseless Strehl, or its d50 within 10 %) per registration method, converted to the I
magnitude of a star giving that signal through the case's own collecting area in its frames
(:mod:`luckyao.photometry`: the figure's ``photometry``, the same zero point, band and throughput
at every size). A larger aperture collects more photons of the same star, and AO-corrected
frames concentrate them: the knee moves to fainter stars.
"""

import numpy as np
import xarray as xr

from ..photometry import Photometry, case_aperture
from .diameter import series_points
from .registration import REGISTRATION_METRICS, registration_data
from .settings import FigureSettings
from .style import LINE_STYLES, MARKERS, colour, new_figure

KNEE_LABELS = {
    "strehl": "Strehl knee: 90 % of the noiseless Strehl",
    "d50_arcsec": "d50 knee: within 10 % of the noiseless d50",
}


def limiting_magnitude_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per series, diameter, registration method, criterion, fraction and read noise: each
    metric's knee in detected photons per frame and as an I magnitude (NaN: never reached;
    at the sweep's faintest signal: a bound, flagged)."""
    series, diameters, where = series_points(settings)
    signals = registration_data(settings, datasets)
    knee_dims = [d for d in signals["strehl_knee_photons"].dims if d != "case"]  # registration, criterion, ...
    shape = (len(series), len(diameters)) + tuple(signals.sizes[d] for d in knee_dims)
    faintest = float(signals.signal.values[0])
    photometry = Photometry.from_config(settings.photometry)
    data = {}
    for metric in REGISTRATION_METRICS:
        photons, magnitude = np.full(shape, np.nan), np.full(shape, np.nan)
        for (label, diameter), i in where.items():
            knee = signals[f"{metric}_knee_photons"].isel(case=i).transpose(*knee_dims).values
            cell = series.index(label), diameters.index(diameter)
            photons[cell] = knee
            magnitude[cell] = photometry.magnitude(knee, *case_aperture(settings.case_configs[settings.cases[i]]))
        dims = ("series", "diameter", *knee_dims)
        data[f"{metric}_knee_photons"] = (
            dims,
            photons,
            {"units": "1", "long_name": f"detected photons per frame at the {KNEE_LABELS[metric]} (NaN: never)"},
        )
        data[f"{metric}_knee_i_mag"] = (
            dims,
            magnitude,
            {
                "units": "1",
                "long_name": f"I magnitude of a star at the {KNEE_LABELS[metric]}, through the case's aperture",
            },
        )
        data[f"{metric}_knee_is_bound"] = (
            dims,
            (photons == faintest).astype(np.int8),
            {
                "units": "1",
                "long_name": "1 where the knee is the sweep's faintest signal: the value holds down to it, "
                "the limit is fainter (a bound)",
            },
        )
    cases = np.full((len(series), len(diameters)), "", dtype=object)
    for (label, diameter), i in where.items():
        cases[series.index(label), diameters.index(diameter)] = settings.cases[i]
    coords = {
        "series": ("series", series, {"long_name": "AO mode and beacon height"}),
        "diameter": ("diameter", diameters, {"units": "m", "long_name": "telescope diameter"}),
        "case": (("series", "diameter"), cases.astype(str), {"long_name": "the case of each point ('' none)"}),
    }
    coords.update({d: signals[d] for d in knee_dims})
    dropped = ("i_zero_photons_per_frame", "photometric_apertures")  # per case: each its own aperture
    return xr.Dataset(data, coords=coords, attrs={k: v for k, v in signals.attrs.items() if k not in dropped})


def draw_limiting_magnitude(ds: xr.Dataset, title: str):
    """A column per metric: the knee's I magnitude vs the diameter, a colour per series, a line
    style per registration method; the figure's first criterion, fraction and read noise; a
    knee at the sweep's faintest signal drawn open (a bound)."""
    first = {d: ds[d].values[0] for d in ("criterion", "fraction", "read_noise")}
    fig = new_figure(12, 5.2)
    axes = fig.subplots(1, len(REGISTRATION_METRICS), squeeze=False)[0]
    for ax, metric in zip(axes, REGISTRATION_METRICS):
        for s, series in enumerate(ds.series.values):
            for k, method in enumerate(ds.registration.values):
                cell = ds.sel(series=series, registration=method, **first)
                magnitude = cell[f"{metric}_knee_i_mag"].values
                bound = cell[f"{metric}_knee_is_bound"].values.astype(bool)
                ax.plot(
                    ds.diameter.values,
                    magnitude,
                    color=colour(s),
                    ls=LINE_STYLES[k % 4],
                    marker=MARKERS[k % 8],
                    label=f"{series}, {method}",
                )
                ax.plot(ds.diameter.values[bound], magnitude[bound], "o", ms=9, mfc="none", color=colour(s))
        ax.set_xlabel("telescope diameter [m]")
        ax.set_ylabel(f"limiting {ds.attrs.get('photometric_band', 'I')} magnitude (fainter up)")
        ax.set_title(KNEE_LABELS[metric], loc="left", fontsize=9)
        ax.grid(alpha=0.3)
    fig.legend(
        *axes[0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=min(4, ds.sizes["series"] * ds.sizes["registration"]),
        fontsize=8,
        title=f"colour: AO and beacons; line style: registration; selection by {first['criterion']}, "
        f"{first['fraction']:.0%} of frames, read noise {first['read_noise']:g} e-; open circle: a bound "
        "(the knee at the faintest signal swept)",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: limiting magnitude of the lucky-imaging reference star vs telescope diameter")
    return fig
