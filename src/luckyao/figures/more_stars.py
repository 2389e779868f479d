"""An off-axis target registered on 1, 2, 4... stars (a case's ``stars``): its integrated Strehl
and d50 against the brightest star's detected signal, and the knees against the number of stars."""

import numpy as np
import xarray as xr
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from ..photometry import Photometry
from .registration import REGISTRATION_METRICS, knees, magnitude_axis, zero_magnitude_photons
from .settings import FigureSettings, case_coords
from .style import CRITERIA, LINE_STYLES, MARKERS, METRICS, colour, new_figure

DRAWN_METHODS = ("cog", "xcorr")
"""The registration methods drawn (those of the cases; the dataset keeps every one): the baseline and
the best at low signal."""


def more_stars_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per case, count of stars, registration method, criterion, fraction, read noise and the brightest
    star's signal: the science target's ``strehl`` and ``d50_arcsec``, the same selection and shifts
    on the noiseless frames (``*_noiseless``), the noiseless detector's (``*_noiseless_detector``), and
    each curve's knee (:func:`.registration.knees`, ``*_knee_photons``); the stars' separations and
    differential tilts, measured and in theory."""
    criteria, fractions, read_noise = list(settings.criteria), list(settings.fractions), list(settings.read_noise_e)
    sweep = settings.sweep_detectors
    signal = np.unique([d["photons_per_frame"] for d in sweep.values()])
    names = [
        [next(k for k, d in sweep.items() if d["read_noise_e"] == r and d["photons_per_frame"] == n) for n in signal]
        for r in read_noise
    ]  # (read noise, signal)
    first = datasets[0]
    noiseless = str(first.detector[np.isnan(first.photons_per_frame.values)].values[0])
    dims = ("n_stars", "registration", "criterion", "fraction")

    def cell(ds, name):
        return ds[f"stars_{name}"].sel(criterion=criteria, fraction=fractions).transpose(*dims, "detector")

    data = {}
    for metric in REGISTRATION_METRICS:
        for name in (metric, f"{metric}_noiseless"):
            values = [np.stack([cell(ds, name).sel(detector=row).values for row in names], axis=-2) for ds in datasets]
            data[name] = (("case", *dims, "read_noise", "signal"), np.stack(values), dict(first[f"stars_{name}"].attrs))
        data[f"{metric}_noiseless_detector"] = (
            ("case", *dims),
            np.stack([cell(ds, metric).sel(detector=noiseless).values for ds in datasets]),
            {**first[f"stars_{metric}"].attrs, "long_name": "the same, noiseless detector"},
        )
    for name in (
        "star_separation_arcsec",
        "star_differential_tilt_variance_px2",
        "star_differential_tilt_variance_theory_px2",
    ):
        data[name] = (("case", "star", "axis"), np.stack([ds[name].values for ds in datasets]), dict(first[name].attrs))
    ds = xr.Dataset(
        data,
        coords={
            **case_coords(settings, datasets),
            "n_stars": ("n_stars", first.n_stars.values, dict(first.n_stars.attrs)),
            "registration": (
                "registration",
                [str(m) for m in first.registration.values],
                {"long_name": "registration method"},
            ),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion (the brightest star's image)"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
            "read_noise": (
                "read_noise",
                read_noise,
                {"units": "1", "long_name": "read noise rms per pixel in electrons"},
            ),
            "signal": (
                "signal",
                signal,
                {"units": "1", "long_name": "the brightest star's detected photons per frame"},
            ),
            "axis": ("axis", ["y", "x"], {"long_name": "image axis"}),
            "zero_magnitude_photons_per_frame": (
                "case",
                zero_magnitude_photons(settings),
                {
                    "units": "1",
                    "long_name": "detected photons per frame of a magnitude-0 star through the case's aperture "
                    "in its frames (luckyao.photometry; the magnitude axis)",
                },
            ),
            "pixel_scale_arcsec": ((), settings.case(settings.cases[0]).camera.pixel_scale_arcsec, {"units": "arcsec"}),
        },
    )
    for metric in REGISTRATION_METRICS:
        ds[f"{metric}_knee_photons"] = knees(ds, metric)
    ds.attrs["photometric_band"] = Photometry.from_config(settings.photometry).band
    return ds


def draw_more_stars(ds: xr.Dataset, title: str):
    """Columns: case x read noise. Rows: Strehl and d50 against the brightest star's signal (colour:
    number of stars; line style: registration method; thin lines: noiseless detector), then the knees
    against the number of stars (one colour after the counts'; marker: method; line style: metric).
    The first criterion and fraction."""
    criterion, fraction = ds.criterion.values[0], float(ds.fraction.values[0])
    methods = [m for m in ds.registration.values if m in DRAWN_METHODS] or list(ds.registration.values)
    columns = [(case, r) for case in ds.case.values for r in ds.read_noise.values]
    fig = new_figure(max(7.5, 3.6 * len(columns)), 11.0)
    axes = fig.subplots(3, len(columns), squeeze=False)
    for c, (case, read_noise) in enumerate(columns):
        at = ds.sel(case=case, criterion=criterion, fraction=fraction)
        for row, metric in enumerate(REGISTRATION_METRICS):
            ax = axes[row, c]
            for k, n in enumerate(ds.n_stars.values):
                for s, method in enumerate(methods):
                    line = at.sel(n_stars=n, registration=method)
                    ax.plot(
                        ds.signal,
                        line[f"{metric}_noiseless"].sel(read_noise=read_noise),
                        color=colour(k),
                        ls=LINE_STYLES[s % 4],
                        marker=MARKERS[k % 8],
                        ms=3,
                        label=f"{n} star{'s' if n > 1 else ''}, {method}",
                    )
                    ax.axhline(
                        float(line[f"{metric}_noiseless_detector"]), color=colour(k), lw=0.5, ls=LINE_STYLES[s % 4]
                    )
            ax.set_xscale("log")
            if metric == "d50_arcsec":
                ax.set_yscale("log")
                ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
                ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel("brightest star's photons per frame", fontsize=8)
            if c == 0:
                ax.set_ylabel(METRICS[metric])
            ax.grid(alpha=0.3)
            zero = float(ds.zero_magnitude_photons_per_frame.sel(case=case))
            magnitude_axis(ax, zero, ds.signal.values, f"{ds.attrs['photometric_band']} magnitude" if row == 0 else "")
            panel = chr(ord("a") + row * len(columns) + c)
            ax.set_title(
                f"({panel}) {ds.label.sel(case=case).values}, read noise {read_noise:g} e-",
                loc="left",
                fontsize=9,
            )
        ax = axes[2, c]
        for k, method in enumerate(methods):
            for s, metric in enumerate(REGISTRATION_METRICS):
                ax.plot(
                    ds.n_stars,
                    at[f"{metric}_knee_photons"].sel(registration=method, read_noise=read_noise),
                    color=colour(len(ds.n_stars)),  # not a count of stars' colour: methods by marker
                    marker=MARKERS[(len(ds.n_stars) + k) % 8],  # nor a count's marker
                    ls=LINE_STYLES[s % 4],
                    label=f"{method}, {'Strehl' if metric == 'strehl' else 'd50'} knee",
                )
        ax.set_yscale("log")
        ax.set_xticks(ds.n_stars.values)
        ax.set_xlabel("number of stars")
        if c == 0:
            ax.set_ylabel("knee [brightest star's\nphotons per frame]")
        ax.grid(alpha=0.3)
        ax.set_title(f"({chr(ord('a') + 2 * len(columns) + c)}) knees", loc="left", fontsize=9)
    handles, labels = (
        sum(pair, []) for pair in zip(axes[0, 0].get_legend_handles_labels(), axes[2, 0].get_legend_handles_labels())
    )
    last = chr(ord("a") + 2 * len(columns) - 1)
    fig.legend(
        handles,
        labels,
        loc="outside lower center",
        ncol=5,
        fontsize=8,
        title=f"(a-{last}) {100 * fraction:g} % of frames selected by the brightest star's "
        f"{CRITERIA.get(criterion, criterion)}, scored on the noiseless frames; colour: stars registered on; "
        "line style: registration; thin lines: noiseless detector\nknees: the signal from which the Strehl stays "
        "at >= 90 % (the d50 within 10 %) of the noiseless detector's with as many stars",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: an off-axis target registered on several stars")
    return fig
