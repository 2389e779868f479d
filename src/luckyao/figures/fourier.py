"""Fourier lucky imaging against shift-and-add (:mod:`luckyao.lucky.fourier`): the integrated
image's Strehl and d50 against the fraction of frames kept, per case (the noiseless detector, the
baseline registration ``cog``), and, where a case has the detector sweep, its Strehl against the
detected signal per frame (the noisy frames' selection and shifts applied to the noiseless frames,
as the registration figure scores them)."""

import numpy as np
import xarray as xr

from .settings import FigureSettings, case_coords
from .style import AO_STYLE, CRITERIA, LINE_STYLES, MARKERS, METRICS, SCREEN_INCHES, colour, fraction_axis, new_figure

FOURIER_METRICS = ("strehl", "d50_arcsec")


def fourier_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per case (first target): shift-and-add's ``strehl`` and ``d50_arcsec`` (case, criterion,
    fraction) and Fourier lucky imaging's ``fourier_strehl``, ``fourier_d50_arcsec`` and
    ``fourier_d50_beyond_crop`` (case, fraction) of the figure's detector at its fractions; with
    ``read_noise_e``, the same Strehls of every noisy detector of that read noise applied to the
    noiseless frames, ``strehl_noiseless`` (case, criterion, fraction, read_noise, signal) and
    ``fourier_strehl_noiseless`` (case, fraction, read_noise, signal), NaN where a case has no such
    detector."""
    criteria, fractions, read_noise = list(settings.criteria), list(settings.fractions), list(settings.read_noise_e)
    first = [ds.isel(target=0) for ds in datasets]
    detector = settings.detector
    data = {}
    for metric in FOURIER_METRICS:
        data[metric] = (
            ("case", "criterion", "fraction"),
            np.array(
                [
                    [ds[metric].sel(criterion=c, detector=detector, fraction=fractions).values for c in criteria]
                    for ds in first
                ]
            ),
            dict(first[0][metric].attrs),
        )
        data[f"fourier_{metric}"] = (
            ("case", "fraction"),
            np.array(
                [ds[f"fourier_{metric}"].sel(detector=detector, fourier_fraction=fractions).values for ds in first]
            ),
            dict(first[0][f"fourier_{metric}"].attrs),
        )
    data["fourier_d50_beyond_crop"] = (
        ("case", "fraction"),
        np.array(
            [ds.fourier_d50_beyond_crop.sel(detector=detector, fourier_fraction=fractions).values for ds in first]
        ),
        dict(first[0].fourier_d50_beyond_crop.attrs),
    )
    coords = {
        **case_coords(settings, datasets),
        "criterion": ("criterion", criteria, {"long_name": "shift-and-add's selection criterion"}),
        "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames kept"}),
    }
    if read_noise:
        photons = [ds.photons_per_frame.values for ds in first]
        signal = np.unique(np.concatenate([p[np.isfinite(p)] for p in photons]))
        names = [
            [[_named(ds, r, n) for n in signal] for r in read_noise] for ds in first
        ]  # (case, read noise, signal): the detector's name or None
        clean = np.full((len(first), len(criteria), len(fractions), len(read_noise), len(signal)), np.nan)
        fourier_clean = np.full((len(first), len(fractions), len(read_noise), len(signal)), np.nan)
        for c, (ds, grid) in enumerate(zip(first, names)):
            for r, row in enumerate(grid):
                for s, name in enumerate(row):
                    if name is None:
                        continue
                    clean[c, :, :, r, s] = ds.strehl_noiseless.sel(
                        criterion=criteria, fraction=fractions, detector=name
                    )
                    fourier_clean[c, :, r, s] = ds.fourier_strehl_noiseless.sel(
                        fourier_fraction=fractions, detector=name
                    )
        dims = ("case", "criterion", "fraction", "read_noise", "signal")
        data["strehl_noiseless"] = (dims, clean, dict(first[0].strehl_noiseless.attrs))
        data["fourier_strehl_noiseless"] = (
            tuple(d for d in dims if d != "criterion"),
            fourier_clean,
            dict(first[0].fourier_strehl_noiseless.attrs),
        )
        coords["read_noise"] = (
            "read_noise",
            read_noise,
            {"units": "1", "long_name": "read noise rms per pixel in electrons"},
        )
        coords["signal"] = ("signal", signal, {"units": "1", "long_name": "detected photons per lucky frame (a count)"})
    return xr.Dataset(data, coords=coords, attrs={"detector": detector})


def _named(ds: xr.Dataset, read_noise: float, photons: float) -> str | None:
    """The name of ``ds``'s detector of ``read_noise`` and ``photons`` per frame, or None."""
    match = (ds.read_noise_e.values == read_noise) & (ds.photons_per_frame.values == photons)
    return str(ds.detector.values[match][0]) if match.any() else None


def draw_fourier(ds: xr.Dataset, title: str):
    """Strehl and d50 against the fraction kept (colour: case; Fourier lucky imaging solid with
    circles, shift-and-add by each criterion in another line style and marker; a d50 that is a lower
    bound open) and, with the detector sweep, the Strehl on the noiseless frames against the signal
    per frame, a panel per fraction."""
    signal = "signal" in ds.dims and np.isfinite(ds.fourier_strehl_noiseless.values).any()
    panels = [(metric, None) for metric in FOURIER_METRICS]
    if signal:
        panels += [("signal", (r, f)) for r in ds.read_noise.values for f in ds.fraction.values]
    fig = new_figure(SCREEN_INCHES[0], 4.2 if len(panels) <= 3 else SCREEN_INCHES[1])
    n_cols = min(len(panels), 3 if len(panels) <= 3 else 4)
    axes = fig.subplots(-(-len(panels) // n_cols), n_cols, squeeze=False).ravel()
    percent = 100 * ds.fraction.values
    for ax, (metric, cell) in zip(axes, panels):
        for k, case in enumerate(ds.case.values):
            at = ds.sel(case=case)
            if metric != "signal":
                bound = at.fourier_d50_beyond_crop.values.astype(bool) if metric == "d50_arcsec" else None
                y = at[f"fourier_{metric}"].values
                ax.plot(percent, y, color=colour(k), ls="-", marker="o", ms=5, lw=1.6)
                if bound is not None and bound.any():
                    ax.plot(percent[bound], y[bound], ls="", marker="o", ms=9, mfc="none", color=colour(k))
                for j, criterion in enumerate(ds.criterion.values):
                    ax.plot(
                        percent,
                        at[metric].sel(criterion=criterion).values,
                        color=colour(k),
                        ls=LINE_STYLES[(j + 1) % 4],
                        marker=MARKERS[(j + 1) % 8],
                        ms=4,
                        lw=1.0,
                    )
                continue
            read_noise, fraction = cell
            x = ds.signal.values
            ls = AO_STYLE.get(str(at.ao_mode.values), "-")
            ax.plot(
                x,
                at.fourier_strehl_noiseless.sel(read_noise=read_noise, fraction=fraction),
                color=colour(k),
                ls=ls,
                marker="o",
                ms=5,
                lw=1.6,
            )
            for j, criterion in enumerate(ds.criterion.values):
                ax.plot(
                    x,
                    at.strehl_noiseless.sel(criterion=criterion, read_noise=read_noise, fraction=fraction),
                    color=colour(k),
                    ls=LINE_STYLES[(j + 1) % 4],
                    marker=MARKERS[(j + 1) % 8],
                    ms=4,
                    lw=1.0,
                )
        if metric == "signal":
            ax.set_xscale("log")
            ax.set_xlabel("detected photons per frame")
            ax.set_ylabel("Strehl ratio (on the noiseless frames)")
            ax.set_title(f"{cell[0]:g} e- read noise, {100 * cell[1]:g} % kept", fontsize=9)
        else:
            fraction_axis(ax)
            ax.set_ylabel(METRICS[metric])
        ax.grid(alpha=0.3)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    handles = [
        axes[0].plot([], [], color=colour(k), lw=2, label=str(label))[0] for k, label in enumerate(ds.label.values)
    ]
    handles.append(axes[0].plot([], [], color="grey", ls="-", marker="o", label="Fourier lucky imaging")[0])
    handles += [
        axes[0].plot(
            [],
            [],
            color="grey",
            ls=LINE_STYLES[(j + 1) % 4],
            marker=MARKERS[(j + 1) % 8],
            label=f"shift-and-add, {CRITERIA.get(str(c), str(c))}",
        )[0]
        for j, c in enumerate(ds.criterion.values)
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4), fontsize=8, frameon=False)
    fig.suptitle(
        f"{title}: Fourier lucky imaging against shift-and-add ({ds.attrs['detector']} detector, cog)", fontsize=11
    )
    return fig
