"""Long-exposure figures: the simulated long exposure beside the analytic one, and a
table of every case's long-exposure and best lucky Strehl (also as Markdown)."""

import numpy as np
import xarray as xr

from ..optics.long_exposure import long_exposure_strehl
from .settings import FigureSettings, case_coords
from .style import colour, new_figure


def long_exposure_check_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Simulated long-exposure Strehl (no recentring) beside the analytic value."""
    detector = settings.detector
    simulated, error, analytic = [], [], []
    for name, ds in zip(settings.cases, datasets):
        case = settings.case(name)
        simulated.append(float(ds["long_exposure_strehl"].sel(recentring="none", detector=detector).isel(target=0)))
        error.append(float(ds["long_exposure_strehl_error"].isel(target=0)))
        analytic.append(
            long_exposure_strehl(case.telescope, case.camera.wavelength_m, case.r0_samples_m(), case.outer_scale_m)
        )
    attrs = {"units": "1"}
    return xr.Dataset(
        {
            "simulated": ("case", simulated, {**attrs, "long_name": "simulated long-exposure Strehl ratio"}),
            "simulated_error": (
                "case",
                error,
                {
                    **attrs,
                    "long_name": "Monte-Carlo standard error of simulated (batch means of the per-frame axis value)",
                },
            ),
            "analytic": (
                "case",
                analytic,
                {**attrs, "long_name": "analytic long-exposure Strehl ratio, telescope OTF x exp(-D_phi/2)"},
            ),
        },
        coords=case_coords(settings, datasets),
        attrs={"detector": detector},
    )


def draw_long_exposure_check(ds: xr.Dataset, title: str):
    fig = new_figure(7, 4.5)
    ax = fig.subplots()
    x = np.arange(ds.sizes["case"])
    ax.errorbar(
        x - 0.08, ds.simulated, yerr=ds.simulated_error, fmt="o", capsize=3, color=colour(0), label="simulated ±1σ"
    )
    ax.plot(x + 0.08, ds.analytic, "s", color=colour(1), label="analytic")
    ax.set_xticks(x, [f"{c}\nmean r0 {r:.1f} cm" for c, r in zip(ds.case.values, ds.r0_cm.values)], fontsize=8)
    ax.set_ylabel("long-exposure Strehl ratio (no recentring)")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return fig


def long_exposure_table_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Every case's long-exposure Strehl (all frames) without and with recentring, and its
    best lucky Strehl (the largest over the observable criteria, not the oracle
    ``true_rms``, and the fractions, and where it is), each with
    its Monte-Carlo standard error from time blocks."""
    detector = settings.detector
    strehl = [ds["long_exposure_strehl"].sel(detector=detector).isel(target=0).values for ds in datasets]
    error = [
        [
            float(ds["long_exposure_strehl_error"].isel(target=0)),
            float(ds["recentred_long_exposure_strehl_error"].sel(detector=detector).isel(target=0)),
        ]
        for ds in datasets
    ]
    observable = [[c for c in ds.criterion.values if c != "true_rms"] for ds in datasets]  # not the oracle
    lucky = [ds.strehl.sel(detector=detector, criterion=c).isel(target=0) for ds, c in zip(datasets, observable)]
    best = [np.unravel_index(int(np.argmax(s.values)), s.shape) for s in lucky]  # (criterion, fraction)
    data = {
        "long_exposure_strehl": (
            ("case", "recentring"),
            np.array(strehl),
            dict(datasets[0]["long_exposure_strehl"].attrs),
        ),
        "long_exposure_strehl_error": (
            ("case", "recentring"),
            np.array(error),
            {"units": "1", "long_name": "Monte-Carlo standard error of the long-exposure Strehl (batch means)"},
        ),
        "best_lucky_strehl": (
            "case",
            [float(s.values[b]) for s, b in zip(lucky, best)],
            {"units": "1", "long_name": "largest integrated-image Strehl over the observable criteria and fractions"},
        ),
        "best_criterion": (
            "case",
            [str(s.criterion.values[b[0]]) for s, b in zip(lucky, best)],
            {"long_name": "selection criterion of the best lucky Strehl"},
        ),
        "best_fraction": (
            "case",
            [float(s.fraction.values[b[1]]) for s, b in zip(lucky, best)],
            {"units": "1", "long_name": "fraction of frames of the best lucky Strehl"},
        ),
    }
    if all("strehl_error" in ds for ds in datasets):
        data["best_lucky_strehl_error"] = (
            "case",
            [
                float(ds.strehl_error.sel(detector=detector, criterion=c).isel(target=0).values[b])
                for ds, c, b in zip(datasets, observable, best)
            ],
            {"units": "1", "long_name": "Monte-Carlo standard error of the best lucky Strehl (time blocks)"},
        )
    return xr.Dataset(
        data,
        coords={**case_coords(settings, datasets), "recentring": datasets[0]["recentring"]},
        attrs={"detector": detector},
    )


def value_with_error(value: float, error: float) -> str:
    """``value ± error`` with the error to two significant digits and the value to the same
    decimal place (at least three decimals): ``0.00521 ± 0.00012``, ``0.220 ± 0.003``."""
    value, error = float(value), float(error)
    decimals = 3
    if np.isfinite(error) and error > 0:
        decimals = max(3, 1 - int(np.floor(np.log10(error))))
    return f"{value:.{decimals}f} ± {error:.{decimals}f}"


def long_exposure_markdown(ds: xr.Dataset) -> str:
    """The table of :func:`long_exposure_table_data` as Markdown (for the README)."""

    def pm(value, error=None):
        return f"{float(value):.3f}" if error is None else value_with_error(value, error)

    lines = ["| case | long exposure | recentred | best lucky (criterion, fraction) |", "|---|---|---|---|"]
    for case in ds.case.values:
        row = ds.sel(case=case)
        le = [
            pm(row.long_exposure_strehl.sel(recentring=r), row.long_exposure_strehl_error.sel(recentring=r))
            for r in ("none", "cog")
        ]
        best = pm(row.best_lucky_strehl, row.best_lucky_strehl_error if "best_lucky_strehl_error" in row else None)
        lines.append(
            f"| {case} | {le[0]} | {le[1]} | {best} ({row.best_criterion.values}, "
            f"{100 * float(row.best_fraction):g} %) |"
        )
    return "\n".join(lines) + "\n"


def draw_long_exposure_table(ds: xr.Dataset, title: str):
    n = ds.sizes["case"]
    fig = new_figure(11, 0.32 * n + 1.2)
    ax = fig.subplots()
    ax.axis("off")

    def best(row):
        error = f" ± {float(row.best_lucky_strehl_error):.4f}" if "best_lucky_strehl_error" in row else ""
        return (
            f"{float(row.best_lucky_strehl):.4f}{error} ({row.best_criterion.values}, "
            f"{100 * float(row.best_fraction):g} %)"
        )

    cells = [
        [f"{row.case.values} ({row.summary.values})"]
        + [
            f"{float(row.long_exposure_strehl.sel(recentring=r)):.4f} ± "
            f"{float(row.long_exposure_strehl_error.sel(recentring=r)):.4f}"
            for r in ("none", "cog")
        ]
        + [best(row)]
        for row in (ds.sel(case=case) for case in ds.case.values)
    ]
    table = ax.table(
        cells,
        colLabels=["case", "long exposure", "recentred (centroid)", "best lucky Strehl (criterion, fraction)"],
        loc="center",
        cellLoc="left",
        colWidths=[0.46, 0.15, 0.15, 0.24],
    )
    table.auto_set_font_size(False)
    table.set_fontsize(7.5)
    table.scale(1, 1.25)
    ax.set_title(f"{title}: long-exposure Strehl of every case (all frames, {ds.attrs['detector']}), ±1σ")
    return fig
