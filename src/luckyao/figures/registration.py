"""Integrated-image quality vs detected signal per frame for every registration method, with
the signal as an I magnitude, and the knees: the signal below which a method loses its
noiseless quality."""

from dataclasses import replace
from functools import partial

import numpy as np
import xarray as xr
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from ..photometry import Photometry, case_aperture, magnitude_of, photons_of
from .settings import FigureSettings
from .signal import signal_data
from .style import CRITERIA, LINE_STYLES, MARKERS, METRICS, colour, new_figure

REGISTRATION_METRICS = ("strehl", "d50_arcsec")
"""The figure's metrics: the integrated image's Strehl and 50%-energy diameter."""

KNEE_TOLERANCE = {"strehl": 0.9, "d50_arcsec": 1.1}
"""A knee: the signal above which the value stays at >= 90 % of the noiseless Strehl, or within
10 % of the noiseless d50 (the value with the noiseless detector, same method and selection).
The values are those of the noisy frames' selection and shifts applied to the noiseless frames
(``*_noiseless``): the noisy image's own Strehl is biased up at low signal, where a method that
registers on the brightest noise speckle piles the noise peaks up on the axis."""


def zero_magnitude_photons(settings: FigureSettings) -> np.ndarray:
    """Per case of the figure, detected photons per frame of a magnitude-0 star through its
    aperture in its frames (:meth:`luckyao.photometry.Photometry.photons_at_zero_magnitude`, the
    figure's ``photometry``)."""
    photometry = Photometry.from_config(settings.photometry)
    return np.array(
        [photometry.photons_at_zero_magnitude(*case_aperture(settings.case_configs[name])) for name in settings.cases]
    )


def registration_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """:func:`.signal.signal_data` of Strehl and d50 for every registration method of
    the cases (along ``registration``), with each curve's knee (:func:`knees`)."""
    methods = [str(m) for m in datasets[0].registration.values]
    per_method = []
    for method in methods:
        chosen = [ds.sel(registration=method) for ds in datasets]
        per_metric = [signal_data(_with_metric(settings, metric), chosen) for metric in REGISTRATION_METRICS]
        # each variable keeps its attributes; the datasets' own (their metric) differ and go
        per_method.append(xr.merge(per_metric, compat="override", combine_attrs="drop_conflicts"))
    ds = xr.concat(per_method, dim="registration", data_vars="all", coords="minimal", compat="override")
    ds = ds.assign_coords(registration=("registration", methods, {"long_name": "registration method"}))
    for metric in REGISTRATION_METRICS:
        ds[f"{metric}_knee_photons"] = knees(ds, metric)
    photometry = Photometry.from_config(settings.photometry)
    zero = zero_magnitude_photons(settings)
    ds = ds.assign_coords(
        zero_magnitude_photons_per_frame=(
            "case",
            zero,
            {
                "units": "1",
                "long_name": f"detected photons per frame of a {photometry.band} = 0 star through the case's aperture "
                "in its frames (luckyao.photometry; the magnitude axis and the knees' magnitudes)",
            },
        )
    )
    ds.attrs.update(
        i_zero_photons_per_frame=float(zero[0]),
        i_zero_point_w_m2_um=photometry.zero_point_w_m2_um,
        i_bandwidth_um=photometry.bandwidth_um,
        throughput=photometry.throughput,
        frame_time_s=case_aperture(settings.case_configs[settings.cases[0]])[1],
        photometric_band=photometry.band,
        photometric_wavelength_um=photometry.wavelength_um,
        photometric_apertures=", ".join(
            sorted({f"{settings.case(name).telescope.diameter_m:g} m" for name in settings.cases})
        ),
    )
    return ds


def _with_metric(settings: FigureSettings, metric: str) -> FigureSettings:
    return replace(settings, metric=metric)


def knees(ds: xr.Dataset, metric: str) -> xr.DataArray:
    """Per curve, the lowest signal [photons per frame] from which the value of the noisy
    selection and shifts on the noiseless frames (``<metric>_noiseless``) stays within
    :data:`KNEE_TOLERANCE` of the noiseless detector's (interpolated in log signal between the
    last point outside and the first inside); NaN when even the highest signal is outside, the
    lowest signal when every point is inside."""
    value = ds[f"{metric}_noiseless"].transpose(..., "signal")
    reference = ds[f"{metric}_noiseless_detector"]
    ratio = (value / reference).transpose(..., "signal")
    tolerance = KNEE_TOLERANCE[metric]
    inside = ratio >= tolerance if metric == "strehl" else ratio <= tolerance
    log_signal = np.log10(ds.signal.values)
    flat_inside = inside.values.reshape(-1, ds.sizes["signal"])
    flat_ratio = ratio.values.reshape(-1, ds.sizes["signal"])
    out = np.full(len(flat_inside), np.nan)
    for j, (ok, r) in enumerate(zip(flat_inside, flat_ratio)):
        if not ok[-1]:
            continue
        outside = np.flatnonzero(~ok)
        if not outside.size:
            out[j] = ds.signal.values[0]
            continue
        a = outside[-1]  # last point outside; a + 1 inside
        t = (tolerance - r[a]) / (r[a + 1] - r[a]) if np.isfinite(r[a]) and r[a + 1] != r[a] else 1.0
        out[j] = 10 ** (log_signal[a] + np.clip(t, 0, 1) * (log_signal[a + 1] - log_signal[a]))
    return xr.DataArray(
        out.reshape(inside.shape[:-1]),
        dims=inside.dims[:-1],
        attrs={
            "units": "1",
            "long_name": f"detected photons per frame (a count) from which {metric} stays within "
            f"{abs(1 - tolerance):.0%} of the noiseless detector's (NaN: never)",
        },
    )


def magnitude_axis(ax, zero_photons: float, signal: np.ndarray, label: str) -> None:
    """The top axis of a panel against detected photons per frame ``signal`` (ascending): the
    magnitude of a star giving them (:func:`luckyao.photometry.magnitude_of`, ``zero_photons`` at
    magnitude 0), a tick every 2 magnitudes."""
    top = ax.secondary_xaxis(
        "top",
        functions=(partial(magnitude_of, zero_photons=zero_photons), partial(photons_of, zero_photons=zero_photons)),
    )
    magnitudes = magnitude_of(signal[[-1, 0]], zero_photons)
    top.set_xticks(np.arange(np.ceil(magnitudes[0]), np.floor(magnitudes[1]) + 1, 2))
    top.xaxis.set_major_formatter(FormatStrFormatter("%g"))
    top.xaxis.set_minor_formatter(NullFormatter())
    top.set_xlabel(label, fontsize=8)


def zero_photons_of(ds: xr.Dataset, case) -> float:
    """A registration figure's photons per frame at magnitude 0 for ``case`` (its
    ``zero_magnitude_photons_per_frame``; a dataset drawn before it had one: ``i_zero_photons_per_frame``)."""
    if "zero_magnitude_photons_per_frame" in ds.coords:
        return float(ds.zero_magnitude_photons_per_frame.sel(case=case))
    return float(ds.attrs["i_zero_photons_per_frame"])


def knee_markdown(ds: xr.Dataset, fraction: float, criterion: str, read_noise: float) -> str:
    """The knees of a registration figure's dataset as a Markdown table: a row per case and method."""
    band = ds.attrs.get("photometric_band", "I")
    lines = [
        f"| case | registration | Strehl knee [photons/frame] ({band} mag) | d50 knee [photons/frame] ({band} mag) |",
        "|---|---|---|---|",
    ]
    for case in ds.case.values:
        zero = zero_photons_of(ds, case)
        for method in ds.registration.values:
            cells = []
            for metric in REGISTRATION_METRICS:
                knee = float(
                    ds[f"{metric}_knee_photons"].sel(
                        case=case, registration=method, fraction=fraction, criterion=criterion, read_noise=read_noise
                    )
                )
                at_most = "≤ " if knee == ds.signal.values[0] else ""  # inside down to the lowest signal drawn
                cells.append(
                    "not reached"
                    if np.isnan(knee)
                    else f"{at_most}{knee:.3g} ({band} {'≥ ' if at_most else ''}{magnitude_of(knee, zero):.1f})"
                )
            lines.append(f"| {ds.label.sel(case=case).values} | {method} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines)


def draw_registration(ds: xr.Dataset, title: str):
    """Rows: metric; columns: case x read noise; colour and marker: registration method; line
    style: selection criterion; the first fraction of the figure; I magnitude on the top axis."""
    fraction = float(ds.fraction.values[0])
    band = ds.attrs.get("photometric_band", "I")
    columns = [(case, read_noise) for case in ds.case.values for read_noise in ds.read_noise.values]
    n_rows, n_cols = len(REGISTRATION_METRICS), len(columns)
    fig = new_figure(3.4 * n_cols, 3.2 * n_rows + 1.6)
    axes = fig.subplots(n_rows, n_cols, squeeze=False, sharex=True)
    for row, metric in enumerate(REGISTRATION_METRICS):
        for c, (case, read_noise) in enumerate(columns):
            ax = axes[row, c]
            for k, method in enumerate(ds.registration.values):
                for s, criterion in enumerate(ds.criterion.values):
                    cell = ds.sel(
                        case=case,
                        criterion=criterion,
                        fraction=fraction,
                        read_noise=read_noise,
                        registration=method,
                    )
                    ax.plot(
                        ds.signal,
                        cell[f"{metric}_noiseless"].values,
                        color=colour(k),
                        ls=LINE_STYLES[s % 4],
                        marker=MARKERS[k % len(MARKERS)],
                        ms=3,
                        label=f"{method}, by {CRITERIA.get(criterion, criterion)}",
                    )
                    bound_flag = f"{metric}_noiseless_field_bound"
                    if bound_flag in cell:  # a d50 set by the field: a lower bound, an open triangle
                        bound = cell[bound_flag].values.astype(bool)
                        values = cell[f"{metric}_noiseless"].values
                        ax.plot(
                            ds.signal.values[bound],
                            values[bound],
                            ls="none",
                            marker="^",
                            mfc="none",
                            ms=7,
                            color=colour(k),
                        )
                    ax.axhline(
                        float(cell[f"{metric}_noiseless_detector"]),
                        color=colour(k),
                        lw=0.5,
                        ls=LINE_STYLES[s % 4],
                        alpha=0.5,
                    )
            ax.set_xscale("log")
            if c == 0:
                ax.set_ylabel(METRICS[metric])
            if metric == "d50_arcsec":
                ax.set_yscale("log")
                ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
                ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
                ax.yaxis.set_minor_formatter(NullFormatter())
            ax.set_title(
                f"({chr(ord('a') + row * n_cols + c)}) {ds.label.sel(case=case).values},\nread noise {read_noise:g} e-",
                loc="left",
                fontsize=9,
            )
            ax.grid(alpha=0.3)
            magnitude_axis(ax, zero_photons_of(ds, case), ds.signal.values, f"{band} magnitude" if row == 0 else "")
    for ax in axes[-1]:
        ax.set_xlabel("detected photons per frame")
    fig.legend(
        *axes[0, 0].get_legend_handles_labels(),
        loc="outside lower center",
        ncol=4,
        fontsize=8,
        title=f"{100 * fraction:g} % of frames, the noisy frames' selection and shifts scored on the noiseless "
        "frames; colour and marker: registration;\nline style: selection criterion; "
        "thin lines: noiseless detector; open triangles: d50 set by the field (a lower bound).\n"
        f"{band} magnitude: {ds.attrs['i_zero_photons_per_frame']:.3g} "
        f"photons per frame at {band} = 0\n({ds.attrs['i_bandwidth_um'] * 1e3:g} nm band, throughput "
        f"{ds.attrs['throughput']:g}, {ds.attrs['frame_time_s'] * 1e3:g} ms, "
        f"{ds.attrs.get('photometric_apertures', '4.2 m')})",
        title_fontsize=8,
    )
    fig.suptitle(f"{title}: integrated-image quality vs signal per frame,\nby registration method")
    return fig
