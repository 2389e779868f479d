"""Integrated-image quality vs detected signal per frame: the detector sweep."""

import numpy as np
import xarray as xr

from ..lucky.dataset import NOISE_DOMINATED, noise_dominated, noise_flag_attrs
from .settings import FigureSettings, case_coords
from .style import (
    AO_STYLE,
    CRITERIA,
    MARKERS,
    METRICS,
    SCREEN_INCHES,
    colour,
    limit_flags,
    new_figure,
    unflagged,
    with_error,
)


def quality_vs_signal_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """:func:`signal_data` for every registration method the cases share, along ``registration``
    (the lucky datasets' own dimension; ``cog`` alone when they have none)."""
    if not all("registration" in ds.dims for ds in datasets):
        return signal_data(settings, datasets).expand_dims(registration=["cog"])
    methods = [m for m in datasets[0].registration.values if all(m in ds.registration.values for ds in datasets)]
    per_method = [signal_data(settings, [ds.sel(registration=m) for ds in datasets]) for m in methods]
    ds = xr.concat(per_method, dim="registration", data_vars="all", coords="minimal", compat="override")
    return ds.assign_coords(
        registration=("registration", [str(m) for m in methods], {"long_name": "registration method"})
    )


def signal_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Integrated-image quality (first target) vs detected photons per frame over the
    detector sweep, per case, criterion, fraction and read noise, of one registration; with
    the score of the same selection and shifts on the noiseless frames, the noiseless
    detector's, and where the value is noise-dominated (:func:`luckyao.lucky.dataset.noise_dominated`)."""
    metric, criteria, fractions = settings.metric, list(settings.criteria), list(settings.fractions)
    read_noise = list(settings.read_noise_e)
    first = datasets[0]
    sweep = settings.sweep_detectors  # name -> photons_per_frame, read_noise_e
    signal = np.unique([d["photons_per_frame"] for d in sweep.values()])
    names_at = [
        [
            next(name for name, d in sweep.items() if d["read_noise_e"] == r and d["photons_per_frame"] == n)
            for n in signal
        ]
        for r in read_noise
    ]  # (read noise, signal) detector names

    def table(variable):
        return np.array(
            [
                [
                    [
                        [
                            ds[variable].sel(criterion=c, fraction=f, detector=row).isel(target=0).values
                            for row in names_at
                        ]
                        for f in fractions
                    ]
                    for c in criteria
                ]
                for ds in datasets
            ]
        )

    dims = ("case", "criterion", "fraction", "read_noise", "signal")
    data = {name: (dims, table(name), dict(first[name].attrs)) for name in with_error(datasets, metric)}
    if f"{metric}_noiseless" in first:
        clean = table(f"{metric}_noiseless")
        data[f"{metric}_noiseless"] = (dims, clean, dict(first[f"{metric}_noiseless"].attrs))
        flags = noise_dominated(data[metric][1], clean)
        data[f"{metric}_noise_dominated"] = (dims, flags.astype(np.int8), noise_flag_attrs(metric))
    for name in limit_flags(datasets, metric) + limit_flags(datasets, f"{metric}_noiseless"):
        data[name] = (dims, table(name), dict(first[name].attrs))
    noiseless = first.detector[np.isnan(first.photons_per_frame.values)].values
    if noiseless.size:
        reference = [
            [
                [
                    ds[metric].sel(criterion=c, fraction=f, detector=noiseless[0]).isel(target=0).values
                    for f in fractions
                ]
                for c in criteria
            ]
            for ds in datasets
        ]
        data[f"{metric}_noiseless_detector"] = (
            ("case", "criterion", "fraction"),
            np.array(reference),
            {**first[metric].attrs, "long_name": f"{first[metric].attrs['long_name']}, noiseless detector"},
        )
    return xr.Dataset(
        data,
        coords={
            **case_coords(settings, datasets),
            "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
            "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
            "read_noise": (
                "read_noise",
                read_noise,
                {"units": "1", "long_name": "read noise rms per pixel in electrons"},
            ),
            "signal": ("signal", signal, {"units": "1", "long_name": "detected photons per lucky frame (a count)"}),
        },
        attrs={"metric": metric},
    )


def draw_quality_vs_signal(ds: xr.Dataset, title: str):
    """One screen of small panels on shared axes: a row per registration method, a column
    per (read noise, fraction); colour and marker: criterion; line style: case."""
    metric = ds.attrs["metric"]
    columns = [(read_noise, fraction) for read_noise in ds.read_noise.values for fraction in ds.fraction.values]
    n_rows, n_cols = ds.sizes["registration"], len(columns)
    fig = new_figure(*SCREEN_INCHES)
    axes = fig.subplots(n_rows, n_cols, squeeze=False, sharex=True, sharey=True)
    for r, method in enumerate(ds.registration.values):
        for f, (read_noise, fraction) in enumerate(columns):
            ax = axes[r, f]
            for case in ds.case.values:
                ls = AO_STYLE[str(ds.ao_mode.sel(case=case).values)]
                for k, criterion in enumerate(ds.criterion.values):
                    cell = ds.sel(
                        case=case, criterion=criterion, fraction=fraction, read_noise=read_noise, registration=method
                    )
                    y = unflagged(cell, metric)
                    ax.plot(
                        ds.signal,
                        y,
                        marker=MARKERS[k % 8],
                        ms=3,
                        color=colour(k),
                        ls=ls,
                        label=f"{cell.label.values}, by {CRITERIA.get(criterion, criterion)}",
                    )
                    if f"{metric}_error" in cell:  # the band of the points drawn
                        error = cell[f"{metric}_error"].values
                        ax.fill_between(ds.signal.values, y - error, y + error, color=colour(k), alpha=0.18, lw=0)
                    if f"{metric}_noiseless_detector" in ds:
                        ax.axhline(
                            float(cell[f"{metric}_noiseless_detector"]), color=colour(k), lw=0.6, ls=ls, alpha=0.6
                        )
            ax.set_xscale("log")
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if r == 0:
                ax.set_title(f"read noise {read_noise:g} e-\n{100 * fraction:g} % of frames", fontsize=8)
            if r == n_rows - 1:
                ax.set_xlabel("photons per frame", fontsize=8)
        axes[r, 0].set_ylabel(method, fontsize=9, fontweight="bold")
    fig.supylabel(METRICS[metric], fontsize=9)
    # the axis spans the values the noise leaves alone: at a few photons the recentring fails
    # and the images blur far off the scale (arcsec)
    settled = [ds[metric].isel(signal=-1).max()] + (
        [ds[f"{metric}_noiseless_detector"].max()] if f"{metric}_noiseless_detector" in ds else []
    )
    axes[0, 0].set_ylim(0.0, 1.5 * float(max(settled)))
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=3,
        fontsize=8,
        title="rows: registration method; colour and marker: selection criterion; line style: case; thin "
        "horizontal lines: noiseless detector\n"
        f"bands: ±1 Monte-Carlo standard error; points more than {NOISE_DOMINATED:.0%} off the same "
        "selection on the noiseless frames\nare noise-dominated and left out, as are values beyond the "
        "diffraction limit and d50 set by the field (bounds); values above the axis: blurred by recentring on noise",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image {METRICS[metric]} vs signal per frame")
    return fig
