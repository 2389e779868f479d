"""Fourier lucky imaging against shift-and-add (:mod:`luckyao.lucky.fourier`): the integrated
image's Strehl and d50 against the fraction of frames kept, per case (the noiseless detector, the
baseline registration ``cog``), and, where a case has the detector sweep, its Strehl against the
detected signal per frame (the noisy frames' selection and shifts applied to the noiseless frames,
as the registration figure scores them)."""

import numpy as np
import xarray as xr

from .settings import FigureSettings, case_coords
from .style import CRITERIA, LINE_STYLES, MARKERS, METRICS, SCREEN_INCHES, colour, fraction_axis, new_figure

FOURIER_METRICS = ("strehl", "d50_arcsec")
FOURIER_VARIABLES = (
    "fourier_strehl",
    "fourier_d50_arcsec",
    "fourier_d50_beyond_crop",
    "fourier_strehl_error",
    "fourier_d50_arcsec_error",
)
"""A lucky dataset's Fourier variables the figure takes at its detector (the errors: with time blocks)."""


def fourier_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per registration method (every one a case has; NaN where a case has not) and case (first
    target): shift-and-add's ``strehl`` and ``d50_arcsec`` (registration, case, criterion, fraction)
    and Fourier lucky imaging's ``fourier_strehl``, ``fourier_d50_arcsec`` and
    ``fourier_d50_beyond_crop`` (registration, case, fraction) of the figure's detector at its
    fractions; with ``read_noise_e``, the same Strehls of every noisy detector of that read noise
    applied to the noiseless frames, ``strehl_noiseless`` (..., criterion, fraction, read_noise,
    signal) and ``fourier_strehl_noiseless`` (..., fraction, read_noise, signal), NaN where a case
    has no such detector."""
    criteria, fractions, read_noise = list(settings.criteria), list(settings.fractions), list(settings.read_noise_e)
    detector, cases = settings.detector, [ds.isel(target=0) for ds in datasets]
    methods = list(dict.fromkeys(str(m) for ds in cases for m in _methods(ds)))
    cells = [[_of_method(ds, m) for ds in cases] for m in methods]  # (method, case): a dataset or None
    template = cases[0] if "registration" not in cases[0].dims else cases[0].isel(registration=0)
    photons = np.concatenate([ds.photons_per_frame.values for ds in cases])
    signal = np.unique(photons[np.isfinite(photons)]) if read_noise else np.array([])
    shape = (len(methods), len(cases))
    n_c, n_f, n_r, n_s = len(criteria), len(fractions), len(read_noise), len(signal)
    values = {metric: np.full((*shape, n_c, n_f), np.nan) for metric in FOURIER_METRICS}
    values |= {f"{metric}_error": np.full((*shape, n_c, n_f), np.nan) for metric in FOURIER_METRICS}
    values |= {
        f"fourier_{metric}{e}": np.full((*shape, n_f), np.nan) for metric in FOURIER_METRICS for e in ("", "_error")
    }
    values["fourier_d50_beyond_crop"] = np.zeros((*shape, n_f), np.int8)
    values["strehl_noiseless"] = np.full((*shape, n_c, n_f, n_r, n_s), np.nan)
    values["fourier_strehl_noiseless"] = np.full((*shape, n_f, n_r, n_s), np.nan)
    values["fourier_strehl_noiseless_error"] = np.full((*shape, n_f, n_r, n_s), np.nan)
    for i, row in enumerate(cells):
        for c, ds in enumerate(row):
            if ds is None:
                continue
            for metric in FOURIER_METRICS:
                for name in (metric, f"{metric}_error"):
                    if name in ds:  # errors: with time blocks
                        values[name][i, c] = ds[name].sel(criterion=criteria, detector=detector, fraction=fractions)
            for name in FOURIER_VARIABLES:
                if name in ds:
                    values[name][i, c] = ds[name].sel(detector=detector, fourier_fraction=fractions)
            for r, noise in enumerate(read_noise):
                for k, n in enumerate(signal):
                    name = _named(ds, noise, n)
                    if name is not None:
                        values["strehl_noiseless"][i, c, :, :, r, k] = ds.strehl_noiseless.sel(
                            criterion=criteria, fraction=fractions, detector=name
                        )
                        for var in ("fourier_strehl_noiseless", "fourier_strehl_noiseless_error"):
                            if var in ds:
                                values[var][i, c, :, r, k] = ds[var].sel(fourier_fraction=fractions, detector=name)
    dims = {
        "strehl": ("criterion", "fraction"),
        "d50_arcsec": ("criterion", "fraction"),
        "strehl_error": ("criterion", "fraction"),
        "d50_arcsec_error": ("criterion", "fraction"),
        "strehl_noiseless": ("criterion", "fraction", "read_noise", "signal"),
        "fourier_strehl_noiseless": ("fraction", "read_noise", "signal"),
        "fourier_strehl_noiseless_error": ("fraction", "read_noise", "signal"),
    }
    data = {
        name: (("registration", "case", *dims.get(name, ("fraction",))), value, dict(template[name].attrs))
        for name, value in values.items()
        if (read_noise or "noiseless" not in name) and name in template
    }
    coords = {
        **case_coords(settings, datasets),
        "registration": ("registration", methods, {"long_name": "registration method"}),
        "criterion": ("criterion", criteria, {"long_name": "shift-and-add's selection criterion"}),
        "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames kept"}),
    }
    if read_noise:
        coords["read_noise"] = ("read_noise", read_noise, {"units": "1", "long_name": "read noise rms per pixel in e-"})
        coords["signal"] = ("signal", signal, {"units": "1", "long_name": "detected photons per lucky frame (a count)"})
    return xr.Dataset(data, coords=coords, attrs={"detector": detector})


def _error(ds: xr.Dataset, name: str, at: dict):
    """``name``'s Monte-Carlo error at ``at`` (±1 sigma error bars), or None (no time blocks)."""
    return ds[f"{name}_error"].sel(**at).values if f"{name}_error" in ds else None


def _methods(ds: xr.Dataset) -> list[str]:
    return [str(m) for m in ds.registration.values] if "registration" in ds.dims else ["cog"]


def _of_method(ds: xr.Dataset, method: str) -> xr.Dataset | None:
    """``ds``'s results of registration ``method``, or None."""
    if "registration" not in ds.dims:
        return ds if method == "cog" else None
    return ds.sel(registration=method) if method in ds.registration.values else None


def _named(ds: xr.Dataset, read_noise: float, photons: float) -> str | None:
    """The name of ``ds``'s detector of ``read_noise`` and ``photons`` per frame, or None."""
    match = (ds.read_noise_e.values == read_noise) & (ds.photons_per_frame.values == photons)
    return str(ds.detector.values[match][0]) if match.any() else None


def draw_fourier(ds: xr.Dataset, title: str):
    """A row per registration method: Strehl and d50 against the fraction kept (colour: case; Fourier
    lucky imaging solid with circles, shift-and-add by each criterion in another line style and
    marker; a d50 that is a lower bound circled) and, with the detector sweep, the Strehl on the
    noiseless frames against the signal per frame, a panel per read noise and fraction below 100 %
    (at 100 % both keep every frame: the same image)."""
    signal = "signal" in ds.dims and np.isfinite(ds.fourier_strehl_noiseless.values).any()
    panels = [(metric, None) for metric in FOURIER_METRICS]
    if signal:
        panels += [("signal", (r, f)) for r in ds.read_noise.values for f in ds.fraction.values if f < 1]
    n_rows = ds.sizes["registration"]
    fig = new_figure(SCREEN_INCHES[0], min(SCREEN_INCHES[1], 1.0 + 3.2 * n_rows))
    axes = fig.subplots(n_rows, len(panels), squeeze=False)
    percent = 100 * ds.fraction.values
    for row, method in zip(axes, ds.registration.values):
        for ax, (metric, cell) in zip(row, panels):
            at = ds.sel(registration=method)
            for k, case in enumerate(ds.case.values):
                if metric == "signal":
                    x = ds.signal.values
                    cell_at = {"case": case, "read_noise": cell[0], "fraction": cell[1]}
                    fourier = at.fourier_strehl_noiseless.sel(**cell_at)
                    fourier_error = _error(at, "fourier_strehl_noiseless", cell_at)
                    saa = [at.strehl_noiseless.sel(criterion=c, **cell_at) for c in ds.criterion.values]
                    saa_error = [None] * len(saa)  # the noiseless scores of shift-and-add: no blocks
                else:
                    x = percent
                    fourier = at[f"fourier_{metric}"].sel(case=case).values
                    fourier_error = _error(at, f"fourier_{metric}", {"case": case})
                    saa = [at[metric].sel(case=case, criterion=c) for c in ds.criterion.values]
                    saa_error = [_error(at, metric, {"case": case, "criterion": c}) for c in ds.criterion.values]
                    if metric == "d50_arcsec":
                        bound = at.fourier_d50_beyond_crop.sel(case=case).values.astype(bool)
                        ax.plot(x[bound], fourier[bound], ls="", marker="o", ms=9, mfc="none", color=colour(k))
                ax.errorbar(x, fourier, fourier_error, color=colour(k), ls="-", marker="o", ms=5, lw=1.6, capsize=2)
                for j, (values, error) in enumerate(zip(saa, saa_error)):
                    style = {"ls": LINE_STYLES[(j + 1) % 4], "marker": MARKERS[(j + 1) % 8]}
                    ax.errorbar(x, values, error, color=colour(k), ms=4, lw=1.0, capsize=2, **style)
            if metric == "signal":  # the quantity in the title: y labels would run into the next panel
                ax.set_xscale("log")
                ax.set_xlabel("detected photons per frame")
                ax.set_title(f"{method}, {cell[0]:g} e-, {100 * cell[1]:g} % kept: Strehl (noiseless)", fontsize=8)
            else:
                fraction_axis(ax)
                ax.set_title(f"{method}: {METRICS[metric]}", fontsize=8)
            ax.grid(alpha=0.3)
    first = axes[0, 0]
    handles = [
        first.plot([], [], color=colour(k), lw=2, label=str(label))[0] for k, label in enumerate(ds.label.values)
    ]
    handles.append(first.plot([], [], color="grey", ls="-", marker="o", label="Fourier lucky imaging")[0])
    for j, c in enumerate(ds.criterion.values):
        style = {"ls": LINE_STYLES[(j + 1) % 4], "marker": MARKERS[(j + 1) % 8]}
        handles.append(
            first.plot([], [], color="grey", label=f"shift-and-add, {CRITERIA.get(str(c), str(c))}", **style)[0]
        )
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4), fontsize=8, frameon=False)
    fig.suptitle(f"{title}: Fourier lucky imaging against shift-and-add ({ds.attrs['detector']} detector)", fontsize=11)
    return fig
