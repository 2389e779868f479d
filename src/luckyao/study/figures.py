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

from ..geometry import LineOfSight, footprint_centre_m, footprint_coverage, footprint_scale  # noqa: E402
from ..optics.long_exposure import long_exposure_strehl  # noqa: E402
from ..units import ARCSEC_RAD  # noqa: E402
from .case import Case, lgs_from, targets_from  # noqa: E402
from .config import sha256  # noqa: E402
from .datasets import open_dataset, provenance, write_dataset  # noqa: E402

log = logging.getLogger(__name__)

_METRICS = {
    "strehl": "Strehl ratio",
    "fwhm_arcsec": "FWHM [arcsec]",
    "d50_arcsec": "50% energy diameter [arcsec]",
}
_CRITERIA = {"strehl": "image Strehl", "d50": "50%-energy diameter", "lgs_rms": "LGS open-loop rms",
             "lgs_residual_rms": "LGS pseudo-closed-loop rms", "true_rms": "true corrected rms (oracle)"}
_AO_STYLE = {"ltao": "-", "glao": "-.", "none": "--"}
"""Line style of a case by its AO mode; colours pair the k-th case of each mode."""


def _case_label(name: str, case: dict, r0_cm: float) -> str:
    r0 = f"variable r0, mean {r0_cm:.1f} cm" if case["atmosphere"]["r0_amplitude_m"] > 0 else f"r0 {r0_cm:.1f} cm"
    if case["lgs"]["enabled"]:
        n = case["wfs"]["n_subapertures"]
        r0 += f", {n}x{n} LGS WFS at {case['lgs']['height_m'] / 1e3:.0f} km"
    ao = case["ao"]
    if ao["mode"] != "none":
        r0 += f", {ao['mode'].upper()} {ao['n_actuators']}x{ao['n_actuators']} DM"
    return f"{name} ({r0})"


def _case_coords(settings: dict, names, datasets) -> dict:
    r0_cm = [100 * float(ds["mean_r0_500nm_m"]) for ds in datasets]
    configs = [settings["case_configs"][n] for n in names]
    modes = [c["ao"]["mode"] for c in configs]
    colour = [modes[:i].count(mode) for i, mode in enumerate(modes)]
    return {
        "case": ("case", list(names), {"long_name": "case"}),
        "r0_cm": ("case", r0_cm, {"units": "cm", "long_name": "mean Fried parameter at 500 nm"}),
        "label": ("case", [_case_label(n, c, r) for n, c, r in zip(names, configs, r0_cm)],
                  {"long_name": "legend label"}),
        "ao_mode": ("case", modes, {"long_name": "AO correction: none, ltao or glao"}),
        "colour": ("case", colour, {"units": "1", "long_name": "colour index (k-th case of its AO mode)"}),
    }


def _style(ds: xr.Dataset, case) -> dict:
    row = ds.sel(case=case)
    return {"color": f"C{int(row.colour)}", "ls": _AO_STYLE[str(row.ao_mode.values)]}


def _with_error(datasets, metric: str) -> list[str]:
    """``metric`` and, when every case's lucky dataset has it, its Monte-Carlo error."""
    return [metric] + ([f"{metric}_error"] if all(f"{metric}_error" in ds for ds in datasets) else [])


def _band(ax, x, values: xr.Dataset, metric: str, colour: str) -> None:
    """Shade +-1 standard error around a curve, when the figure's data has it."""
    if f"{metric}_error" in values:
        value, error = values[metric].values, values[f"{metric}_error"].values
        ax.fill_between(np.asarray(x), value - error, value + error, color=colour, alpha=0.18, lw=0)


def quality_vs_fraction_data(settings: dict, names, datasets) -> xr.Dataset:
    """Integrated-image quality (on-axis target) vs fraction selected, per case and criterion."""
    detector, criteria = settings.get("detector", "noiseless"), settings["criteria"]
    data_vars = {}
    for metric in _METRICS:
        for name in _with_error(datasets, metric):
            rows = [ds[name].sel(criterion=criteria, detector=detector).isel(target=0).values for ds in datasets]
            data_vars[name] = (("case", "criterion", "fraction"), np.array(rows), dict(datasets[0][name].attrs))
    long_exposure = [ds["long_exposure_strehl"].sel(detector=detector).isel(target=0).values for ds in datasets]
    data_vars["long_exposure_strehl"] = (("case", "recentring"), np.array(long_exposure),
                                         dict(datasets[0]["long_exposure_strehl"].attrs))
    ds = xr.Dataset(data_vars, coords={**_case_coords(settings, names, datasets),
                                       "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
                                       "fraction": datasets[0]["fraction"],
                                       "recentring": datasets[0]["recentring"]})
    ds.attrs.update(detector=detector)
    return ds


def draw_quality_vs_fraction(ds: xr.Dataset, title: str):
    n_rows = ds.sizes["criterion"]
    fig, axes = plt.subplots(n_rows, 3, figsize=(13, 3.6 * n_rows + 0.6), squeeze=False, constrained_layout=True)
    for r, criterion in enumerate(ds.criterion.values):
        for ax, metric in zip(axes[r], _METRICS):
            for case in ds.case.values:
                row = ds.sel(case=case, criterion=criterion)
                ax.plot(100 * ds.fraction, row[metric], marker="o", ms=3, label=str(row.label.values),
                        **_style(ds, case))
                _band(ax, 100 * ds.fraction, row, metric, _style(ds, case)["color"])
                if metric == "strehl":
                    ax.axhline(float(row.long_exposure_strehl.sel(recentring="none")), lw=0.8,
                               color=_style(ds, case)["color"], ls=":")
            ax.set_xscale("log")
            ax.set_xlabel("frames selected [%]")
            ax.set_ylabel(_METRICS[metric])
            ax.grid(alpha=0.3)
        letter = f"({chr(ord('a') + r)}) " if n_rows > 1 else ""
        axes[r, 0].set_title(f"{letter}selection by {_CRITERIA.get(criterion, criterion)}", loc="left", fontsize=10)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=2, fontsize=7,
               title="solid: LTAO, dash-dot: GLAO, dashed: no AO; dotted: long exposure without recentring; "
                     "bands: +-1 Monte-Carlo standard error (time blocks)",
               title_fontsize=7)
    fig.suptitle(f"{title}: integrated-image quality vs fraction selected, detector {ds.attrs['detector']}")
    return fig


def long_exposure_check_data(settings: dict, names, datasets) -> xr.Dataset:
    """Simulated long-exposure Strehl (no recentring) beside the analytic value."""
    detector = settings.get("detector", "noiseless")
    simulated, error, analytic = [], [], []
    for name, ds in zip(names, datasets):
        case = Case.from_config(settings["case_configs"][name])
        simulated.append(float(ds["long_exposure_strehl"].sel(recentring="none", detector=detector)
                               .isel(target=0)))
        error.append(float(ds["long_exposure_strehl_error"].isel(target=0)))
        analytic.append(long_exposure_strehl(case.telescope, case.camera.wavelength_m, case.r0_samples_m(),
                                             case.outer_scale_m))
    attrs = {"units": "1"}
    return xr.Dataset(
        {
            "simulated": ("case", simulated, {**attrs, "long_name": "simulated long-exposure Strehl ratio"}),
            "simulated_error": ("case", error, {**attrs, "long_name": "Monte-Carlo standard error of simulated "
                                                "(batch means of the per-frame axis value)"}),
            "analytic": ("case", analytic, {**attrs, "long_name": "analytic long-exposure Strehl ratio, "
                                            "telescope OTF x exp(-D_phi/2)"}),
        },
        coords=_case_coords(settings, names, datasets),
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
        lgs = lgs_from(case["lgs"])
        d_m = case["telescope"]["diameter_m"]
        target = targets_from(case["targets_arcsec"][:1])[0]
        for k, h in enumerate(heights):
            footprints = [LineOfSight(*direction, lgs.height_m) for direction in lgs.directions_rad]
            centre[c, k, :lgs.n_beacons] = [footprint_centre_m(los, h) for los in footprints]
            diameter[c, k, :lgs.n_beacons] = d_m * footprint_scale(h, lgs.height_m)
            coverage[c, k] = footprint_coverage(d_m, target, footprints, h)
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
        coords={**_case_coords(settings, names, datasets),
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


def quality_vs_signal_data(settings: dict, names, datasets) -> xr.Dataset:
    """Integrated-image quality (on-axis target) vs detected photons per frame over the
    detector sweep, per case, criterion, fraction and read noise; with the score of the
    same selection and shifts on the noiseless frames, and the noiseless detector's."""
    metric, criteria, fractions = settings["metric"], settings["criteria"], settings["fractions"]
    read_noise = settings["read_noise_e"]
    first = datasets[0]
    sweep = settings["sweep_detectors"]  # name -> photons_per_frame, read_noise_e
    signal = np.unique([d["photons_per_frame"] for d in sweep.values()])
    names_at = [[next(name for name, d in sweep.items() if d["read_noise_e"] == r and d["photons_per_frame"] == n)
                 for n in signal] for r in read_noise]  # (read noise, signal) detector names

    def table(variable):
        return np.array([[[[ds[variable].sel(criterion=c, fraction=f, detector=row).isel(target=0).values
                            for row in names_at] for f in fractions] for c in criteria] for ds in datasets])

    data = {name: (("case", "criterion", "fraction", "read_noise", "signal"), table(name), dict(first[name].attrs))
            for name in _with_error(datasets, metric)}
    if f"{metric}_noiseless" in first:
        data[f"{metric}_noiseless"] = (("case", "criterion", "fraction", "read_noise", "signal"),
                                       table(f"{metric}_noiseless"), dict(first[f"{metric}_noiseless"].attrs))
    noiseless = first.detector[np.isnan(first.photons_per_frame.values)].values
    if noiseless.size:
        reference = [[[ds[metric].sel(criterion=c, fraction=f, detector=noiseless[0]).isel(target=0).values
                       for f in fractions] for c in criteria] for ds in datasets]
        data[f"{metric}_noiseless_detector"] = (("case", "criterion", "fraction"), np.array(reference), {
            **first[metric].attrs, "long_name": f"{first[metric].attrs['long_name']}, noiseless detector"})
    return xr.Dataset(
        data,
        coords={**_case_coords(settings, names, datasets),
                "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
                "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
                "read_noise": ("read_noise", read_noise, {"units": "electron", "long_name": "read noise rms per pixel"}),
                "signal": ("signal", signal, {"units": "photon", "long_name": "detected photons per lucky frame"})},
        attrs={"metric": metric},
    )


def draw_quality_vs_signal(ds: xr.Dataset, title: str):
    metric = ds.attrs["metric"]
    n_rows, n_cols = ds.sizes["read_noise"], ds.sizes["fraction"]
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(4.3 * n_cols, 3.6 * n_rows + 0.9), squeeze=False,
                             sharey=True, constrained_layout=True)
    markers = "os^vD"
    for r, read_noise in enumerate(ds.read_noise.values):
        for f, fraction in enumerate(ds.fraction.values):
            ax = axes[r, f]
            for case in ds.case.values:
                style = _style(ds, case)
                for k, criterion in enumerate(ds.criterion.values):
                    cell = ds.sel(case=case, criterion=criterion, fraction=fraction)
                    label = f"{cell.label.values}, by {_CRITERIA.get(criterion, criterion)}"
                    ax.plot(ds.signal, cell[metric].sel(read_noise=read_noise), marker=markers[k % 5], ms=3.5,
                            label=label, **style)
                    _band(ax, ds.signal, cell.sel(read_noise=read_noise), metric, style["color"])
                    if f"{metric}_noiseless" in ds:  # the same selection and shifts on the noiseless frames
                        ax.plot(ds.signal, cell[f"{metric}_noiseless"].sel(read_noise=read_noise), lw=0.8, ms=2.5,
                                marker=markers[k % 5], color=style["color"], ls=":", alpha=0.8)
                    if f"{metric}_noiseless_detector" in ds:
                        ax.axhline(float(cell[f"{metric}_noiseless_detector"]), color=style["color"], lw=0.6, ls=":")
            ax.set_xscale("log")
            ax.set_xlabel("detected photons per frame")
            ax.set_ylabel(_METRICS[metric])
            ax.set_title(f"({chr(ord('a') + r)}) read noise {read_noise:g} e-, {100 * fraction:g} % of frames",
                         loc="left", fontsize=9)
            ax.grid(alpha=0.3)
    # the axis spans the noise-free values: at a few photons the noise-dominated values run
    # far off (a peak pixel of noise gives Strehl > 1, read noise over the field a d50 of arcsec)
    settled = [ds[metric].isel(signal=-1).max()] + ([ds[f"{metric}_noiseless_detector"].max()]
                                                    if f"{metric}_noiseless_detector" in ds else [])
    axes[0, 0].set_ylim(0.0, 1.5 * float(max(settled)))
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=2, fontsize=7,
               title="markers: selection criterion; thin dotted with markers: the same selection and shifts on "
                     "the noiseless frames; dotted line: noiseless detector; bands: +-1 Monte-Carlo standard error; "
                     "values beyond the axis: noise-dominated", title_fontsize=7)
    fig.suptitle(f"{title}: integrated-image {_METRICS[metric]} vs signal per frame")
    return fig


def quality_vs_distance_data(settings: dict, names, datasets) -> xr.Dataset:
    """Integrated-image quality vs the target's off-axis distance, per case, criterion and
    fraction (field cases: the image criteria and the recentring from the case's reference
    star, ``lgs_rms`` along each target), with each target's mean true residual rms and its
    long-exposure Strehl (no recentring)."""
    detector, criteria, fractions = settings.get("detector", "noiseless"), settings["criteria"], settings["fractions"]
    first = datasets[0]
    distance = np.hypot(first.target_x_arcsec.values, first.target_y_arcsec.values)
    for name, ds in zip(names, datasets):
        other = np.hypot(ds.target_x_arcsec.values, ds.target_y_arcsec.values)
        if other.shape != distance.shape or not np.allclose(other, distance):
            raise ValueError(f"case {name}: targets at {other} arcsec, the first case's at {distance}")
    sel = ("case", "criterion", "fraction", "distance")
    data = {name: (sel, np.array([ds[name].sel(criterion=criteria, fraction=fractions, detector=detector)
                                  .transpose("criterion", "fraction", "target").values for ds in datasets]),
                   dict(first[name].attrs)) for metric in _METRICS for name in _with_error(datasets, metric)}
    data["long_exposure_strehl"] = (("case", "distance"), np.array(
        [ds.long_exposure_strehl.sel(recentring="none", detector=detector).values for ds in datasets]),
        {"units": "1", "long_name": "long-exposure Strehl ratio without recentring"})
    data["mean_true_rms_nm"] = (("case", "distance"), np.array([ds.true_rms_nm.mean("frame").values
                                                                for ds in datasets]),
                                {"units": "nm", "long_name": "mean true tilt-removed residual rms along the target"})
    data["reference_target"] = ("case", [int(ds.reference_target) for ds in datasets],
                                {"units": "1", "long_name": "target that selects and recentres (-1: each its own)"})
    return xr.Dataset(data, coords={
        **_case_coords(settings, names, datasets),
        "criterion": ("criterion", criteria, {"long_name": "selection criterion"}),
        "fraction": ("fraction", fractions, {"units": "1", "long_name": "fraction of frames selected"}),
        "distance": ("distance", distance, {"units": "arcsec", "long_name": "target's off-axis distance"})},
        attrs={"detector": detector})


def draw_quality_vs_distance(ds: xr.Dataset, title: str):
    n_rows = ds.sizes["criterion"]
    fig, axes = plt.subplots(n_rows, 4, figsize=(16, 3.6 * n_rows + 0.9), squeeze=False, constrained_layout=True)
    markers = "os^vDP<>"
    for r, criterion in enumerate(ds.criterion.values):
        for ax, metric in zip(axes[r], _METRICS):
            for case in ds.case.values:
                for k, fraction in enumerate(ds.fraction.values):
                    cell = ds.sel(case=case, criterion=criterion, fraction=fraction)
                    ax.plot(ds.distance, cell[metric], marker=markers[k % 8], ms=3.5,
                            label=f"{cell.label.values}, {100 * fraction:g} %", **_style(ds, case))
                    _band(ax, ds.distance, cell, metric, _style(ds, case)["color"])
            ax.set_xlabel("off-axis distance [arcsec]")
            ax.set_ylabel(_METRICS[metric])
            ax.grid(alpha=0.3)
        axes[r, 0].set_title(f"({chr(ord('a') + r)}) selection by {_CRITERIA.get(criterion, criterion)}",
                             loc="left", fontsize=10)
        axes[r, 3].set_visible(r == 0)
    ax = axes[0, 3]
    for case in ds.case.values:
        ax.plot(ds.distance, ds.mean_true_rms_nm.sel(case=case), marker="o", ms=3.5, **_style(ds, case))
    ax.set_xlabel("off-axis distance [arcsec]")
    ax.set_ylabel("mean true tilt-removed rms [nm]")
    ax.set_title("residual wavefront along the target", loc="left", fontsize=10)
    ax.grid(alpha=0.3)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=3, fontsize=7,
               title="selection (image criteria) and recentring on the on-axis star; lgs_rms along each target; "
                     "solid: LTAO (corrected on axis), dashed: no AO; markers: fraction of frames; "
                     "bands: +-1 Monte-Carlo standard error",
               title_fontsize=7)
    fig.suptitle(f"{title}: integrated-image quality vs off-axis distance, detector {ds.attrs['detector']}")
    return fig


def comparisons_data(settings: dict, names, datasets) -> xr.Dataset:
    """Paired differences ``a - b`` of integrated-image quality vs fraction: two cases (or
    two criteria of one case) that share the turbulence, so the Monte-Carlo error of the
    difference comes from the per-time-block differences (paired), far below the
    unpaired ``sqrt(e_a^2 + e_b^2)`` that the errors of each curve would suggest."""
    detector = settings.get("detector", "noiseless")
    by_name = dict(zip(names, datasets))
    pairs = settings["pairs"]
    data = {}
    for metric, long_name in _METRICS.items():
        value, paired, unpaired = [], [], []
        for pair in pairs:
            a, b = (by_name[pair[k]["case"]][[metric, f"{metric}_error", f"{metric}_block"]].sel(
                criterion=pair[k]["criterion"], detector=detector).isel(target=0) for k in ("a", "b"))
            if a.sizes["block"] != b.sizes["block"]:
                raise ValueError(f"pair {pair['label']}: {a.sizes['block']} and {b.sizes['block']} time blocks")
            blocks = (a[f"{metric}_block"] - b[f"{metric}_block"]).values  # (block, fraction)
            value.append((a[metric] - b[metric]).values)
            paired.append(blocks.std(axis=0, ddof=1) / np.sqrt(blocks.shape[0]))
            unpaired.append(np.hypot(a[f"{metric}_error"].values, b[f"{metric}_error"].values))
        units = datasets[0][metric].attrs["units"]
        dims = ("pair", "fraction")
        data[metric] = (dims, np.array(value), {"units": units, "long_name": f"difference a - b: {long_name}"})
        data[f"{metric}_error"] = (dims, np.array(paired), {
            "units": units, "long_name": "paired Monte-Carlo standard error of the difference (time blocks)"})
        data[f"{metric}_unpaired_error"] = (dims, np.array(unpaired), {
            "units": units, "long_name": "unpaired error sqrt(e_a^2 + e_b^2), for comparison"})
    return xr.Dataset(data, coords={
        "pair": ("pair", [p["label"] for p in pairs], {"long_name": "difference a - b"}),
        "a": ("pair", [f"{p['a']['case']} by {p['a']['criterion']}" for p in pairs], {"long_name": "case a"}),
        "b": ("pair", [f"{p['b']['case']} by {p['b']['criterion']}" for p in pairs], {"long_name": "case b"}),
        "fraction": datasets[0]["fraction"]}, attrs={"detector": detector})


def draw_comparisons(ds: xr.Dataset, title: str):
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), squeeze=False, constrained_layout=True)
    x = 100 * ds.fraction.values
    for ax, metric in zip(axes[0], _METRICS):
        for k, pair in enumerate(ds.pair.values):
            row, colour = ds.sel(pair=pair), f"C{k}"
            ax.plot(x, row[metric], marker="o", ms=3, color=colour,
                    label=f"{pair}: {row.a.values} - {row.b.values}")
            _band(ax, x, row, metric, colour)
            for sign in (-1, 1):
                ax.plot(x, row[metric] + sign * row[f"{metric}_unpaired_error"], color=colour, lw=0.6, ls=":")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("frames selected [%]")
        ax.set_ylabel(f"difference of {_METRICS[metric]}")
        ax.grid(alpha=0.3)
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncol=2, fontsize=7,
               title="bands: paired +-1 standard error (time blocks, shared turbulence); dotted: unpaired +-1 "
                     "standard error", title_fontsize=7)
    fig.suptitle(f"{title}: paired differences of integrated-image quality, detector {ds.attrs['detector']}")
    return fig


def _correlations(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    from scipy.stats import pearsonr, spearmanr

    return float(pearsonr(estimate, truth)[0]), float(spearmanr(estimate, truth)[0])


def residuals_data(settings: dict, names, datasets) -> xr.Dataset:
    """Per frame, the open-loop and pseudo-closed-loop LGS rms along the target and the
    true corrected rms, with the correlations of each estimate with the truth, and of the
    pseudo-closed-loop rms with the open-loop rms (the paper: highly correlated, the
    residual consistently lower)."""
    series = {name: np.stack([ds[name].isel(target=0).values for ds in datasets])
              for name in ("lgs_rms_nm", "lgs_residual_rms_nm", "true_rms_nm")}
    estimates = ["lgs_rms_nm", "lgs_residual_rms_nm"]
    pairs = np.array([[_correlations(series[e][c], series["true_rms_nm"][c]) for e in estimates]
                      for c in range(len(datasets))])  # (case, estimate, kind)
    open_loop = np.array([_correlations(series["lgs_residual_rms_nm"][c], series["lgs_rms_nm"][c])
                          for c in range(len(datasets))])  # (case, kind)
    lower = (series["lgs_residual_rms_nm"] < series["lgs_rms_nm"]).mean(axis=1)
    return xr.Dataset(
        {
            **{name: (("case", "frame"), values, dict(datasets[0][name].attrs)) for name, values in series.items()},
            "pearson": (("case", "estimate"), pairs[..., 0],
                        {"units": "1", "long_name": "Pearson correlation with true_rms_nm"}),
            "spearman": (("case", "estimate"), pairs[..., 1],
                         {"units": "1", "long_name": "rank correlation with true_rms_nm"}),
            "pearson_open_loop": (("case",), open_loop[:, 0], {
                "units": "1", "long_name": "Pearson correlation of lgs_residual_rms_nm with lgs_rms_nm"}),
            "spearman_open_loop": (("case",), open_loop[:, 1], {
                "units": "1", "long_name": "rank correlation of lgs_residual_rms_nm with lgs_rms_nm"}),
            "residual_lower_fraction": (("case",), lower, {
                "units": "1", "long_name": "fraction of frames whose lgs_residual_rms_nm is below lgs_rms_nm"}),
        },
        coords={**_case_coords(settings, names, datasets),
                "estimate": ("estimate", estimates, {"long_name": "LGS estimate of the residual"}),
                "time_s": ("frame", datasets[0]["time_s"].values, {"units": "s", "long_name": "frame start time"})},
        attrs={"window_s": settings.get("window_s", 2.0)},
    )


def draw_residuals(ds: xr.Dataset, title: str):
    n = ds.sizes["case"]
    fig, axes = plt.subplots(n, 2, figsize=(13, 3.4 * n + 0.5), squeeze=False, constrained_layout=True,
                             gridspec_kw={"width_ratios": [2.2, 1]})
    shown = ds.time_s <= float(ds.time_s[0]) + ds.attrs["window_s"]
    names = {"lgs_rms_nm": "open loop", "lgs_residual_rms_nm": "pseudo-closed loop"}
    for c, case in enumerate(ds.case.values):
        row = ds.sel(case=case)
        series, scatter = axes[c]
        series.plot(ds.time_s[shown], row.true_rms_nm[shown], color="k", lw=1.2, label="true corrected rms")
        for k, (name, label) in enumerate(names.items()):
            r = row.sel(estimate=name)
            series.plot(ds.time_s[shown], row[name][shown], color=f"C{k}", lw=0.9, label=label)
            scatter.plot(row.true_rms_nm, row[name], ".", ms=2, color=f"C{k}",
                         label=f"{label}: r = {float(r.pearson):.2f}, rank r = {float(r.spearman):.2f}")
        series.set_title(str(row.label.values), loc="left", fontsize=9)
        series.set_xlabel("time [s]")
        series.set_ylabel("tilt-removed rms along the target [nm]")
        scatter.set_xlabel("true corrected rms [nm]")
        scatter.set_ylabel("LGS-reconstructed rms [nm]")
        series.legend(fontsize=7)
        scatter.legend(fontsize=7, markerscale=5)
        for ax in (series, scatter):
            ax.grid(alpha=0.3)
    fig.suptitle(f"{title}: reconstructed tilt-removed rms, open loop vs pseudo-closed loop, and the truth")
    return fig


def long_exposure_table_data(settings: dict, names, datasets) -> xr.Dataset:
    """Every case's long-exposure Strehl (all frames) without and with recentring, and its
    best lucky Strehl (the largest over the observable criteria, not the oracle
    ``true_rms``, and the fractions, and where it is), each with
    its Monte-Carlo standard error from time blocks."""
    detector = settings.get("detector", "noiseless")
    strehl = [ds["long_exposure_strehl"].sel(detector=detector).isel(target=0).values for ds in datasets]
    error = [[float(ds["long_exposure_strehl_error"].isel(target=0)),
              float(ds["recentred_long_exposure_strehl_error"].sel(detector=detector).isel(target=0))]
             for ds in datasets]
    observable = [[c for c in ds.criterion.values if c != "true_rms"] for ds in datasets]  # not the oracle
    lucky = [ds.strehl.sel(detector=detector, criterion=c).isel(target=0) for ds, c in zip(datasets, observable)]
    best = [np.unravel_index(int(np.argmax(s.values)), s.shape) for s in lucky]  # (criterion, fraction)
    data = {
        "long_exposure_strehl": (("case", "recentring"), np.array(strehl),
                                 dict(datasets[0]["long_exposure_strehl"].attrs)),
        "long_exposure_strehl_error": (("case", "recentring"), np.array(error), {
            "units": "1", "long_name": "Monte-Carlo standard error of the long-exposure Strehl (batch means)"}),
        "best_lucky_strehl": ("case", [float(s.values[b]) for s, b in zip(lucky, best)], {
            "units": "1", "long_name": "largest integrated-image Strehl over the observable criteria and fractions"}),
        "best_criterion": ("case", [str(s.criterion.values[b[0]]) for s, b in zip(lucky, best)],
                           {"long_name": "selection criterion of the best lucky Strehl"}),
        "best_fraction": ("case", [float(s.fraction.values[b[1]]) for s, b in zip(lucky, best)],
                          {"units": "1", "long_name": "fraction of frames of the best lucky Strehl"}),
    }
    if all("strehl_error" in ds for ds in datasets):
        data["best_lucky_strehl_error"] = ("case", [
            float(ds.strehl_error.sel(detector=detector, criterion=c).isel(target=0).values[b])
            for ds, c, b in zip(datasets, observable, best)],
            {"units": "1", "long_name": "Monte-Carlo standard error of the best lucky Strehl (time blocks)"})
    return xr.Dataset(data, coords={**_case_coords(settings, names, datasets),
                                    "recentring": datasets[0]["recentring"]}, attrs={"detector": detector})


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
        le = [pm(row.long_exposure_strehl.sel(recentring=r), row.long_exposure_strehl_error.sel(recentring=r))
              for r in ("none", "cog")]
        best = pm(row.best_lucky_strehl, row.best_lucky_strehl_error if "best_lucky_strehl_error" in row else None)
        lines.append(f"| {case} | {le[0]} | {le[1]} | {best} ({row.best_criterion.values}, "
                     f"{100 * float(row.best_fraction):g} %) |")
    return "\n".join(lines) + "\n"


def draw_long_exposure_table(ds: xr.Dataset, title: str):
    n = ds.sizes["case"]
    fig, ax = plt.subplots(figsize=(11, 0.32 * n + 1.2), constrained_layout=True)
    ax.axis("off")
    def best(row):
        error = f" ± {float(row.best_lucky_strehl_error):.4f}" if "best_lucky_strehl_error" in row else ""
        return (f"{float(row.best_lucky_strehl):.4f}{error} ({row.best_criterion.values}, "
                f"{100 * float(row.best_fraction):g} %)")

    cells = [[str(row.label.values)] + [f"{float(row.long_exposure_strehl.sel(recentring=r)):.4f} ± "
                                        f"{float(row.long_exposure_strehl_error.sel(recentring=r)):.4f}"
                                        for r in ("none", "cog")] + [best(row)]
             for row in (ds.sel(case=case) for case in ds.case.values)]
    table = ax.table(cells, colLabels=["case", "long-exposure Strehl, no recentring",
                                       "recentred (centre of gravity)", "best lucky Strehl"], loc="center",
                     cellLoc="left", colWidths=[0.46, 0.15, 0.15, 0.24])
    table.auto_set_font_size(False)
    table.set_fontsize(7.5)
    table.scale(1, 1.25)
    ax.set_title(f"{title}: long-exposure Strehl of every case (all frames, {ds.attrs['detector']}), ±1σ")
    return fig


FIGURE_KINDS = {
    "asterism": (asterism_data, draw_asterism),
    "rms_truth": (rms_truth_data, draw_rms_truth),
    "quality_vs_fraction": (quality_vs_fraction_data, draw_quality_vs_fraction),
    "long_exposure_check": (long_exposure_check_data, draw_long_exposure_check),
    "long_exposure_table": (long_exposure_table_data, draw_long_exposure_table),
    "quality_vs_signal": (quality_vs_signal_data, draw_quality_vs_signal),
    "quality_vs_distance": (quality_vs_distance_data, draw_quality_vs_distance),
    "comparisons": (comparisons_data, draw_comparisons),
    "residuals": (residuals_data, draw_residuals),
}


def draw_figure(fig_id: str, settings: dict, lucky_paths, out_prefix: str) -> None:
    """Build, save and draw one figure from its cases' lucky datasets (in ``settings['cases']`` order;
    none for geometry-only kinds); ``settings['case_configs']`` holds the cases' resolved configs."""
    datasets = [open_dataset(path, "lucky") for path in lucky_paths]
    make_data, draw = FIGURE_KINDS[settings["kind"]]
    ds = make_data(settings, settings["cases"], datasets)
    ds.attrs.update(provenance(f"luckyao figure {fig_id}", settings, settings.get("seed", 0)))
    ds.attrs["case_config_sha256"] = json.dumps({n: sha256(c) for n, c in settings["case_configs"].items()})
    write_dataset(ds, f"{out_prefix}.nc", allow_nan=set(ds.data_vars))  # drawn data; inputs are checked
    fig = draw(open_dataset(f"{out_prefix}.nc", "figure data"), fig_id)
    for ext in ("pdf", "png"):
        fig.savefig(f"{out_prefix}.{ext}", dpi=150)
    plt.close(fig)
    log.info("figure %s written", fig_id)
