"""Figures of the study: each is a tidy dataset first, then a drawing of it.

``draw_figure`` builds the figure's dataset from the cases' ``lucky.nc`` files,
writes it as ``<prefix>.nc`` and draws ``<prefix>.pdf`` and ``<prefix>.png``
from that dataset alone.
"""

import json
import logging

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from .analytic import long_exposure_strehl  # noqa: E402
from .config import sha256  # noqa: E402
from .datasets import case_config, open_dataset, provenance, write_dataset  # noqa: E402
from .reconstructor import lgs_config  # noqa: E402
from .simulate import System  # noqa: E402
from .units import ARCSEC_RAD  # noqa: E402

log = logging.getLogger(__name__)

_METRICS = {
    "strehl": "Strehl ratio",
    "fwhm_arcsec": "FWHM [arcsec]",
    "d50_arcsec": "50% energy diameter [arcsec]",
}
_CRITERIA = {"strehl": "image Strehl", "d50": "50%-energy diameter", "lgs_rms": "LGS wavefront rms"}


def _case_label(name: str, case: dict, r0_cm: float) -> str:
    r0 = f"variable r0, mean {r0_cm:.1f} cm" if case["atmosphere"]["r0_amplitude_m"] > 0 else f"r0 {r0_cm:.1f} cm"
    if case["lgs"]["enabled"]:
        n = case["wfs"]["n_subapertures"]
        r0 += f", {n}x{n} LGS WFS at {case['lgs']['height_m'] / 1e3:.0f} km"
    return f"{name} ({r0})"


def _case_coords(names, datasets) -> dict:
    r0_cm = [100 * float(ds["mean_r0_500nm_m"]) for ds in datasets]
    labels = [_case_label(n, case_config(ds), r) for n, ds, r in zip(names, datasets, r0_cm)]
    return {
        "case": ("case", list(names), {"long_name": "case"}),
        "r0_cm": ("case", r0_cm, {"units": "cm", "long_name": "mean Fried parameter at 500 nm"}),
        "label": ("case", labels, {"long_name": "legend label"}),
    }


def quality_vs_fraction_data(settings: dict, names, datasets) -> xr.Dataset:
    """Integrated-image quality (on-axis target) vs fraction selected, one curve per case."""
    detector, criterion = settings.get("detector", "noiseless"), settings["criterion"]
    data_vars = {}
    for metric in _METRICS:
        rows = [ds[metric].sel(criterion=criterion, detector=detector).isel(target=0).values
                for ds in datasets]
        data_vars[metric] = (("case", "fraction"), np.array(rows), dict(datasets[0][metric].attrs))
    long_exposure = [ds["long_exposure_strehl"].sel(detector=detector).isel(target=0).values for ds in datasets]
    data_vars["long_exposure_strehl"] = (("case", "recentring"), np.array(long_exposure),
                                         dict(datasets[0]["long_exposure_strehl"].attrs))
    ds = xr.Dataset(data_vars, coords={**_case_coords(names, datasets), "fraction": datasets[0]["fraction"],
                                       "recentring": datasets[0]["recentring"]})
    ds.attrs.update(criterion=criterion, detector=detector)
    return ds


def draw_quality_vs_fraction(ds: xr.Dataset, title: str):
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), constrained_layout=True)
    for ax, metric in zip(axes, _METRICS):
        for i, case in enumerate(ds.case.values):
            row = ds.sel(case=case)
            ax.plot(100 * ds.fraction, row[metric], marker="o", ms=3, color=f"C{i}", label=str(row.label.values))
            if metric == "strehl":
                ax.axhline(float(row.long_exposure_strehl.sel(recentring="none")), color=f"C{i}", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_xlabel("frames selected [%]")
        ax.set_ylabel(_METRICS[metric])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, title="dotted: long exposure, no recentring", title_fontsize=7)
    fig.suptitle(f"{title}: selection by {_CRITERIA.get(ds.attrs['criterion'], ds.attrs['criterion'])}, "
                 f"detector {ds.attrs['detector']}")
    return fig


def long_exposure_check_data(settings: dict, names, datasets) -> xr.Dataset:
    """Simulated long-exposure Strehl (no recentring) beside the analytic value."""
    detector = settings.get("detector", "noiseless")
    simulated, error, analytic = [], [], []
    for ds in datasets:
        system = System.from_config(case_config(ds))
        simulated.append(float(ds["long_exposure_strehl"].sel(recentring="none", detector=detector)
                               .isel(target=0)))
        error.append(float(ds["long_exposure_strehl_error"].isel(target=0)))
        r0_samples = system.r0.r0_m(np.arange(system.n_frames * system.steps_per_frame) * system.time_step_s)
        analytic.append(long_exposure_strehl(system.telescope, system.camera.wavelength_m, r0_samples,
                                             system.outer_scale_m))
    attrs = {"units": "1"}
    return xr.Dataset(
        {
            "simulated": ("case", simulated, {**attrs, "long_name": "simulated long-exposure Strehl ratio"}),
            "simulated_error": ("case", error, {**attrs, "long_name": "Monte-Carlo standard error of simulated "
                                                "(batch means of the per-frame axis value)"}),
            "analytic": ("case", analytic, {**attrs, "long_name": "analytic long-exposure Strehl ratio, "
                                            "telescope OTF x exp(-D_phi/2)"}),
        },
        coords=_case_coords(names, datasets),
        attrs={"detector": detector},
    )


def draw_long_exposure_check(ds: xr.Dataset, title: str):
    fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
    x = np.arange(ds.sizes["case"])
    ax.errorbar(x - 0.08, ds.simulated, yerr=ds.simulated_error, fmt="o", capsize=3, label="simulated ±1σ")
    ax.plot(x + 0.08, ds.analytic, "s", label="analytic")
    ax.set_xticks(x, [f"{c}\nmean r0 {r:.1f} cm" for c, r in zip(ds.case.values, ds.r0_cm.values)], fontsize=8)
    ax.set_ylabel("long-exposure Strehl ratio (no recentring)")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return fig


def asterism_data(settings: dict, names, datasets) -> xr.Dataset:
    """LGS and target pupil footprints at the chosen layer heights (cone effect:
    diameter D (1 - h/H), centre theta h), and the fraction of the target's
    footprint that at least one beacon footprint covers."""
    heights = np.asarray(settings["layer_heights_m"], dtype=float)
    cases = [settings["case_configs"][name] for name in names]
    n_beacons = max(case["lgs"]["n_beacons"] for case in cases)
    centre = np.full((len(cases), len(heights), n_beacons, 2), np.nan)
    diameter = np.full((len(cases), len(heights), n_beacons), np.nan)
    coverage = np.zeros((len(cases), len(heights)))
    for c, case in enumerate(cases):
        lgs = lgs_config(case["lgs"])
        d_m = case["telescope"]["diameter_m"]
        target = np.asarray(case["targets_arcsec"][0]) * ARCSEC_RAD
        for k, h in enumerate(heights):
            centre[c, k, :lgs.n_beacons] = lgs.directions_rad * h
            diameter[c, k, :lgs.n_beacons] = d_m * (1 - h / lgs.height_m)
            grid = np.linspace(-d_m / 2, d_m / 2, 201)
            gx, gy = np.meshgrid(grid, grid)
            inside = np.hypot(gx, gy) <= d_m / 2
            px, py = gx + target[0] * h, gy + target[1] * h
            covered = np.zeros_like(inside)
            for b in range(lgs.n_beacons):
                covered |= np.hypot(px - centre[c, k, b, 0], py - centre[c, k, b, 1]) <= diameter[c, k, b] / 2
            coverage[c, k] = covered[inside].mean()
    return xr.Dataset(
        {
            "footprint_x_m": (("case", "layer_height_m", "beacon"), centre[..., 0],
                              {"units": "m", "long_name": "beacon footprint centre x"}),
            "footprint_y_m": (("case", "layer_height_m", "beacon"), centre[..., 1],
                              {"units": "m", "long_name": "beacon footprint centre y"}),
            "footprint_diameter_m": (("case", "layer_height_m", "beacon"), diameter,
                                     {"units": "m", "long_name": "beacon footprint diameter"}),
            "target_coverage": (("case", "layer_height_m"), coverage,
                                {"units": "1", "long_name": "fraction of the target footprint seen by a beacon"}),
            "beacon_height_m": ("case", [c["lgs"]["height_m"] for c in cases],
                                {"units": "m", "long_name": "beacon height"}),
            "telescope_diameter_m": ((), cases[0]["telescope"]["diameter_m"],
                                     {"units": "m", "long_name": "telescope diameter"}),
            "target_x_m": (("case", "layer_height_m"),
                           np.outer([c["targets_arcsec"][0][0] * ARCSEC_RAD for c in cases], heights),
                           {"units": "m", "long_name": "target footprint centre x"}),
            "target_y_m": (("case", "layer_height_m"),
                           np.outer([c["targets_arcsec"][0][1] * ARCSEC_RAD for c in cases], heights),
                           {"units": "m", "long_name": "target footprint centre y"}),
        },
        coords={"case": ("case", list(names), {"long_name": "case"}),
                "layer_height_m": ("layer_height_m", heights, {"units": "m", "long_name": "layer height"}),
                "beacon": ("beacon", np.arange(n_beacons), {"long_name": "beacon index"})},
    )


def draw_asterism(ds: xr.Dataset, title: str):
    n_case, n_height = ds.sizes["case"], ds.sizes["layer_height_m"]
    fig, axes = plt.subplots(n_case, n_height, figsize=(3 * n_height, 3.1 * n_case), squeeze=False,
                             constrained_layout=True)
    d_m = float(ds.telescope_diameter_m)
    limit = 0.5 * d_m + float(np.nanmax(np.abs(np.stack([ds.footprint_x_m, ds.footprint_y_m])))) + 0.2
    for c in range(n_case):
        for k in range(n_height):
            ax = axes[c, k]
            cell = ds.isel(case=c, layer_height_m=k)
            ax.add_patch(plt.Circle((float(cell.target_x_m), float(cell.target_y_m)), d_m / 2, fill=False,
                                    color="k", lw=1.5, ls="--"))
            for b in range(ds.sizes["beacon"]):
                if np.isfinite(cell.footprint_diameter_m[b]):
                    ax.add_patch(plt.Circle((float(cell.footprint_x_m[b]), float(cell.footprint_y_m[b])),
                                            float(cell.footprint_diameter_m[b]) / 2, alpha=0.25, color=f"C{b}"))
            ax.set_xlim(-limit, limit)
            ax.set_ylim(-limit, limit)
            ax.set_aspect("equal")
            ax.set_title(f"({'ab'[c] if c < 2 else c}) H = {float(cell.beacon_height_m) / 1e3:.0f} km, "
                         f"h = {float(cell.layer_height_m) / 1e3:.2f} km\ncovered {100 * float(cell.target_coverage):.0f}%",
                         fontsize=8)
            ax.set_xlabel("x [m]")
            ax.set_ylabel("y [m]")
    fig.suptitle(f"{title}: LGS footprints (colour) and the target's (dashed)")
    return fig


def rms_truth_data(settings: dict, names, datasets) -> xr.Dataset:
    """Per-frame LGS-reconstructed vs true tilt-removed rms along the target, and
    their Pearson and rank (Spearman) correlations."""
    from scipy.stats import pearsonr, spearmanr

    lgs = np.stack([ds["lgs_rms_nm"].isel(target=0).values for ds in datasets])
    true = np.stack([ds["true_rms_nm"].isel(target=0).values for ds in datasets])
    return xr.Dataset(
        {
            "lgs_rms_nm": (("case", "frame"), lgs, dict(datasets[0]["lgs_rms_nm"].attrs)),
            "true_rms_nm": (("case", "frame"), true, dict(datasets[0]["true_rms_nm"].attrs)),
            "pearson": ("case", [pearsonr(a, b)[0] for a, b in zip(lgs, true)],
                        {"units": "1", "long_name": "Pearson correlation of lgs_rms_nm and true_rms_nm"}),
            "spearman": ("case", [spearmanr(a, b)[0] for a, b in zip(lgs, true)],
                         {"units": "1", "long_name": "rank correlation of lgs_rms_nm and true_rms_nm"}),
        },
        coords={**_case_coords(names, datasets),
                "time_s": ("frame", datasets[0]["time_s"].values, {"units": "s", "long_name": "frame start time"})},
    )


def draw_rms_truth(ds: xr.Dataset, title: str):
    fig, (scatter, series) = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for i, case in enumerate(ds.case.values):
        row = ds.sel(case=case)
        scatter.plot(row.true_rms_nm, row.lgs_rms_nm, ".", ms=2, color=f"C{i}",
                     label=f"{row.label.values}: r = {float(row.pearson):.3f}, rank r = {float(row.spearman):.3f}")
        series.plot(ds.time_s, row.lgs_rms_nm, lw=0.8, color=f"C{i}")
    series.plot(ds.time_s, ds.true_rms_nm.isel(case=0), lw=1.2, color="k", label="true")
    scatter.set_xlabel("true tilt-removed rms along the target [nm]")
    scatter.set_ylabel("LGS-reconstructed tilt-removed rms [nm]")
    scatter.legend(fontsize=7, markerscale=5)
    series.set_xlabel("time [s]")
    series.set_ylabel("tilt-removed rms [nm]")
    series.legend(fontsize=8)
    for ax in (scatter, series):
        ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: how well the LGS criterion tracks the truth")
    return fig


FIGURE_KINDS = {
    "asterism": (asterism_data, draw_asterism),
    "rms_truth": (rms_truth_data, draw_rms_truth),
    "quality_vs_fraction": (quality_vs_fraction_data, draw_quality_vs_fraction),
    "long_exposure_check": (long_exposure_check_data, draw_long_exposure_check),
}


def draw_figure(fig_id: str, settings: dict, lucky_paths, out_prefix: str) -> None:
    """Build, save and draw one figure from its cases' lucky datasets (in ``settings['cases']`` order;
    none for geometry-only kinds); ``settings['case_configs']`` holds the cases' resolved configs."""
    datasets = [open_dataset(path, "lucky") for path in lucky_paths]
    make_data, draw = FIGURE_KINDS[settings["kind"]]
    ds = make_data(settings, settings["cases"], datasets)
    ds.attrs.update(provenance(f"luckyao figure {fig_id}", settings, settings.get("seed", 0)))
    ds.attrs["case_config_sha256"] = json.dumps({n: sha256(c) for n, c in settings["case_configs"].items()})
    write_dataset(ds, f"{out_prefix}.nc")
    fig = draw(open_dataset(f"{out_prefix}.nc", "figure data"), fig_id)
    for ext in ("pdf", "png"):
        fig.savefig(f"{out_prefix}.{ext}", dpi=150)
    plt.close(fig)
    log.info("figure %s written", fig_id)
