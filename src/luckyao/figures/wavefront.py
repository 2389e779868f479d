"""Wavefront figures: the LGS footprints (asterism), and how well the LGS-reconstructed
rms tracks the true one (per frame, open and pseudo-closed loop)."""

import numpy as np
import xarray as xr
from matplotlib.patches import Circle

from ..geometry import LineOfSight, footprint_centre_m, footprint_coverage, footprint_scale
from .settings import FigureSettings, case_coords
from .style import colour, new_figure


def asterism_data(settings: FigureSettings, datasets=()) -> xr.Dataset:
    """LGS and target pupil footprints at the chosen layer heights (cone effect:
    diameter D (1 - h/H), centre theta h), and the fraction of the target's
    footprint that at least one beacon footprint covers."""
    heights = np.asarray(settings.layer_heights_m, dtype=float)
    cases = [settings.case(name) for name in settings.cases]
    for name, case in zip(settings.cases, cases):
        if case.lgs is None:
            raise ValueError(f"asterism figure: case {name} has no LGS (lgs.enabled: false)")
    n_beacons = max(case.lgs.n_beacons for case in cases)
    centre = np.full((len(cases), len(heights), n_beacons, 2), np.nan)
    diameter = np.full((len(cases), len(heights), n_beacons), np.nan)
    coverage = np.zeros((len(cases), len(heights)))
    for c, case in enumerate(cases):
        lgs, d_m, target = case.lgs, case.telescope.diameter_m, case.targets[0]
        for k, h in enumerate(heights):
            footprints = [LineOfSight(*direction, lgs.height_m) for direction in lgs.directions_rad]
            centre[c, k, : lgs.n_beacons] = [footprint_centre_m(los, h) for los in footprints]
            diameter[c, k, : lgs.n_beacons] = d_m * footprint_scale(h, lgs.height_m)
            coverage[c, k] = footprint_coverage(d_m, target, footprints, h)
    dims = ("case", "layer_height_m", "beacon")
    return xr.Dataset(
        {
            "footprint_x_m": (dims, centre[..., 0], {"units": "m", "long_name": "beacon footprint centre x"}),
            "footprint_y_m": (dims, centre[..., 1], {"units": "m", "long_name": "beacon footprint centre y"}),
            "footprint_diameter_m": (dims, diameter, {"units": "m", "long_name": "beacon footprint diameter"}),
            "target_coverage": (
                ("case", "layer_height_m"),
                coverage,
                {"units": "1", "long_name": "fraction of the target footprint seen by a beacon"},
            ),
            "beacon_height_m": (
                "case",
                [c.lgs.height_m for c in cases],
                {"units": "m", "long_name": "beacon height above the telescope", "standard_name": "height"},
            ),
            "telescope_diameter_m": (
                (),
                cases[0].telescope.diameter_m,
                {"units": "m", "long_name": "telescope diameter"},
            ),
            "target_x_m": (
                ("case", "layer_height_m"),
                np.outer([c.targets[0].theta_x_rad for c in cases], heights),
                {"units": "m", "long_name": "target footprint centre x"},
            ),
            "target_y_m": (
                ("case", "layer_height_m"),
                np.outer([c.targets[0].theta_y_rad for c in cases], heights),
                {"units": "m", "long_name": "target footprint centre y"},
            ),
        },
        coords={
            "case": ("case", list(settings.cases), {"long_name": "case"}),
            "layer_height_m": (
                "layer_height_m",
                heights,
                {"units": "m", "long_name": "layer height above the telescope", "standard_name": "height"},
            ),
            "beacon": ("beacon", np.arange(n_beacons), {"units": "1", "long_name": "beacon index"}),
        },
    )


def draw_asterism(ds: xr.Dataset, title: str):
    n_case, n_height = ds.sizes["case"], ds.sizes["layer_height_m"]
    fig = new_figure(3 * n_height, 3.1 * n_case + 0.4)
    axes = fig.subplots(n_case, n_height, squeeze=False)
    d_m = float(ds.telescope_diameter_m)
    limit = 0.5 * d_m + float(np.nanmax(np.abs(np.stack([ds.footprint_x_m, ds.footprint_y_m])))) + 0.2
    for c in range(n_case):
        for k in range(n_height):
            ax = axes[c, k]
            cell = ds.isel(case=c, layer_height_m=k)
            ax.add_patch(
                Circle(
                    (float(cell.target_x_m), float(cell.target_y_m)), d_m / 2, fill=False, color="k", lw=1.5, ls="--"
                )
            )
            for b in range(ds.sizes["beacon"]):
                if np.isfinite(cell.footprint_diameter_m[b]):
                    ax.add_patch(
                        Circle(
                            (float(cell.footprint_x_m[b]), float(cell.footprint_y_m[b])),
                            float(cell.footprint_diameter_m[b]) / 2,
                            alpha=0.3,
                            color=colour(b),
                        )
                    )
            ax.set_xlim(-limit, limit)
            ax.set_ylim(-limit, limit)
            ax.set_aspect("equal")
            ax.set_title(
                f"({chr(ord('a') + c)}) H = {float(cell.beacon_height_m) / 1e3:.0f} km, "
                f"h = {float(cell.layer_height_m) / 1e3:.2f} km\ncovered {100 * float(cell.target_coverage):.0f}%",
                fontsize=8,
            )
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
    fig.suptitle(f"{title}: LGS footprints (a colour per beacon) and the target's (dashed)")
    return fig


def _correlations(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    from scipy.stats import pearsonr, spearmanr

    return float(pearsonr(estimate, truth)[0]), float(spearmanr(estimate, truth)[0])


def rms_truth_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per-frame LGS-reconstructed vs true tilt-removed rms along the target, and
    their Pearson and rank (Spearman) correlations."""
    lgs = np.stack([ds["lgs_rms_nm"].isel(target=0).values for ds in datasets])
    true = np.stack([ds["true_rms_nm"].isel(target=0).values for ds in datasets])
    pairs = np.array([_correlations(a, b) for a, b in zip(lgs, true)])
    return xr.Dataset(
        {
            "lgs_rms_nm": (("case", "frame"), lgs, dict(datasets[0]["lgs_rms_nm"].attrs)),
            "true_rms_nm": (("case", "frame"), true, dict(datasets[0]["true_rms_nm"].attrs)),
            "pearson": (
                "case",
                pairs[:, 0],
                {"units": "1", "long_name": "Pearson correlation of lgs_rms_nm and true_rms_nm"},
            ),
            "spearman": (
                "case",
                pairs[:, 1],
                {"units": "1", "long_name": "rank correlation of lgs_rms_nm and true_rms_nm"},
            ),
        },
        coords={
            **case_coords(settings, datasets),
            "time_s": ("frame", datasets[0]["time_s"].values, {"units": "s", "long_name": "frame start time"}),
        },
    )


def draw_rms_truth(ds: xr.Dataset, title: str):
    fig = new_figure(12, 4.8)
    scatter, series = fig.subplots(1, 2)
    for i, case in enumerate(ds.case.values):
        row = ds.sel(case=case)
        scatter.plot(
            row.true_rms_nm,
            row.lgs_rms_nm,
            ".",
            ms=2,
            color=colour(i),
            label=f"{row.label.values}: r = {float(row.pearson):.3f}, rank r = {float(row.spearman):.3f}",
        )
        series.plot(ds.time_s, row.lgs_rms_nm, lw=0.8, color=colour(i), label=str(row.label.values))
    series.plot(ds.time_s, ds.true_rms_nm.isel(case=0), lw=1.2, color="k", label="true")
    scatter.set_xlabel("true tilt-removed rms along the target [nm]")
    scatter.set_ylabel("LGS-reconstructed tilt-removed rms [nm]")
    scatter.legend(fontsize=8, markerscale=5)
    series.set_xlabel("time [s]")
    series.set_ylabel("tilt-removed rms [nm]")
    series.legend(fontsize=8)
    for ax in (scatter, series):
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: how well the LGS criterion tracks the truth")
    return fig


def residuals_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per frame, the open-loop and pseudo-closed-loop LGS rms along the target and the
    true corrected rms, with the correlations of each estimate with the truth, and of the
    pseudo-closed-loop rms with the open-loop rms (the paper: highly correlated, the
    residual consistently lower)."""
    series = {
        name: np.stack([ds[name].isel(target=0).values for ds in datasets])
        for name in ("lgs_rms_nm", "lgs_residual_rms_nm", "true_rms_nm")
    }
    estimates = ["lgs_rms_nm", "lgs_residual_rms_nm"]
    pairs = np.array(
        [[_correlations(series[e][c], series["true_rms_nm"][c]) for e in estimates] for c in range(len(datasets))]
    )  # (case, estimate, kind)
    open_loop = np.array(
        [_correlations(series["lgs_residual_rms_nm"][c], series["lgs_rms_nm"][c]) for c in range(len(datasets))]
    )  # (case, kind)
    lower = (series["lgs_residual_rms_nm"] < series["lgs_rms_nm"]).mean(axis=1)
    return xr.Dataset(
        {
            **{name: (("case", "frame"), values, dict(datasets[0][name].attrs)) for name, values in series.items()},
            "pearson": (
                ("case", "estimate"),
                pairs[..., 0],
                {"units": "1", "long_name": "Pearson correlation with true_rms_nm"},
            ),
            "spearman": (
                ("case", "estimate"),
                pairs[..., 1],
                {"units": "1", "long_name": "rank correlation with true_rms_nm"},
            ),
            "pearson_open_loop": (
                ("case",),
                open_loop[:, 0],
                {"units": "1", "long_name": "Pearson correlation of lgs_residual_rms_nm with lgs_rms_nm"},
            ),
            "spearman_open_loop": (
                ("case",),
                open_loop[:, 1],
                {"units": "1", "long_name": "rank correlation of lgs_residual_rms_nm with lgs_rms_nm"},
            ),
            "residual_lower_fraction": (
                ("case",),
                lower,
                {"units": "1", "long_name": "fraction of frames whose lgs_residual_rms_nm is below lgs_rms_nm"},
            ),
        },
        coords={
            **case_coords(settings, datasets),
            "estimate": ("estimate", estimates, {"long_name": "LGS estimate of the residual"}),
            "time_s": ("frame", datasets[0]["time_s"].values, {"units": "s", "long_name": "frame start time"}),
        },
        attrs={"window_s": settings.window_s},
    )


def draw_residuals(ds: xr.Dataset, title: str):
    n = ds.sizes["case"]
    fig = new_figure(13, 3.4 * n + 0.5)
    axes = fig.subplots(n, 2, squeeze=False, gridspec_kw={"width_ratios": [2.2, 1]})
    shown = ds.time_s <= float(ds.time_s[0]) + ds.attrs["window_s"]
    names = {"lgs_rms_nm": "open loop", "lgs_residual_rms_nm": "pseudo-closed loop"}
    for c, case in enumerate(ds.case.values):
        row = ds.sel(case=case)
        series, scatter = axes[c]
        series.plot(ds.time_s[shown], row.true_rms_nm[shown], color="k", lw=1.2, label="true corrected rms")
        for k, (name, label) in enumerate(names.items()):
            r = row.sel(estimate=name)
            series.plot(ds.time_s[shown], row[name][shown], color=colour(k), lw=0.9, label=label)
            scatter.plot(
                row.true_rms_nm,
                row[name],
                ".",
                ms=2,
                color=colour(k),
                label=f"{label}: r = {float(r.pearson):.2f}, rank r = {float(r.spearman):.2f}",
            )
        series.set_title(f"({chr(ord('a') + c)}) {row.summary.values}", loc="left", fontsize=9)
        series.set_xlabel("time [s]")
        series.set_ylabel("tilt-removed rms along the target [nm]")
        scatter.set_xlabel("true corrected rms [nm]")
        scatter.set_ylabel("LGS-reconstructed rms [nm]")
        series.legend(fontsize=8)
        scatter.legend(fontsize=8, markerscale=5)
        for ax in (series, scatter):
            ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: reconstructed tilt-removed rms, open loop vs pseudo-closed loop, and the truth")
    return fig
