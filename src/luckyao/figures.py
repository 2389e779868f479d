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
from .datasets import case_config, open_dataset, provenance, write_dataset  # noqa: E402
from .pupil import Telescope  # noqa: E402
from .simulate import System  # noqa: E402

log = logging.getLogger(__name__)

_METRICS = {
    "strehl": "Strehl ratio",
    "fwhm_arcsec": "FWHM [arcsec]",
    "d50_arcsec": "50% energy diameter [arcsec]",
}
_CRITERIA = {"strehl": "image Strehl", "d50": "50%-energy diameter", "lgs_rms": "LGS wavefront rms"}


def _case_label(name: str, r0_cm: float, varies: bool) -> str:
    return f"{name}: variable r0 (mean {r0_cm:.1f} cm)" if varies else f"{name}: r0 = {r0_cm:.1f} cm"


def _case_coords(names, datasets) -> dict:
    r0_cm = [100 * float(ds["mean_r0_500nm_m"]) for ds in datasets]
    varies = [case_config(ds)["atmosphere"]["r0_amplitude_m"] > 0 for ds in datasets]
    return {
        "case": ("case", list(names), {"long_name": "case"}),
        "r0_cm": ("case", r0_cm, {"units": "cm", "long_name": "mean Fried parameter at 500 nm"}),
        "label": ("case", [_case_label(n, r, v) for n, r, v in zip(names, r0_cm, varies)],
                  {"long_name": "legend label"}),
    }


def quality_vs_fraction_data(settings: dict, names, datasets) -> xr.Dataset:
    """Integrated-image quality (on-axis target) vs fraction selected, one curve per case."""
    detector, criterion = settings.get("detector", "noiseless"), settings["criterion"]
    data_vars = {}
    for metric in _METRICS:
        rows = [ds[metric].sel(criterion=criterion, detector=detector).isel(target=0).values
                for ds in datasets]
        data_vars[metric] = (("case", "fraction"), np.array(rows), dict(datasets[0][metric].attrs))
    ds = xr.Dataset(data_vars, coords={**_case_coords(names, datasets),
                                       "fraction": datasets[0]["fraction"]})
    ds.attrs.update(criterion=criterion, detector=detector)
    return ds


def draw_quality_vs_fraction(ds: xr.Dataset, title: str):
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), constrained_layout=True)
    for ax, metric in zip(axes, _METRICS):
        for case in ds.case.values:
            row = ds.sel(case=case)
            ax.plot(100 * ds.fraction, row[metric], marker="o", ms=3, label=str(row.label.values))
        ax.set_xscale("log")
        ax.set_xlabel("frames selected [%]")
        ax.set_ylabel(_METRICS[metric])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
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
        analytic.append(long_exposure_strehl(Telescope(system.telescope.diameter_m, system.telescope.obscuration_m),
                                             system.camera.wavelength_m, r0_samples, system.outer_scale_m))
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
    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    x = np.arange(ds.sizes["case"])
    ax.errorbar(x - 0.08, ds.simulated, yerr=ds.simulated_error, fmt="o", capsize=3, label="simulated ±1σ")
    ax.plot(x + 0.08, ds.analytic, "s", label="analytic")
    ax.set_xticks(x, [str(v) for v in ds.label.values], rotation=20, ha="right", fontsize=8)
    ax.set_ylabel("long-exposure Strehl ratio (no recentring)")
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    return fig


FIGURE_KINDS = {
    "quality_vs_fraction": (quality_vs_fraction_data, draw_quality_vs_fraction),
    "long_exposure_check": (long_exposure_check_data, draw_long_exposure_check),
}


def draw_figure(fig_id: str, settings: dict, lucky_paths, out_prefix: str) -> None:
    """Build, save and draw one figure from its cases' lucky datasets (in ``settings['cases']`` order)."""
    datasets = [open_dataset(path, "lucky") for path in lucky_paths]
    make_data, draw = FIGURE_KINDS[settings["kind"]]
    ds = make_data(settings, settings["cases"], datasets)
    ds.attrs.update(provenance(f"luckyao figure {fig_id}", settings, datasets[0].attrs.get("seed", 0)))
    ds.attrs["case_config_sha256"] = json.dumps({n: d.attrs["config_sha256"] for n, d in zip(settings["cases"], datasets)})
    write_dataset(ds, f"{out_prefix}.nc")
    fig = draw(open_dataset(f"{out_prefix}.nc", "figure data"), fig_id)
    for ext in ("pdf", "png"):
        fig.savefig(f"{out_prefix}.{ext}", dpi=150)
    plt.close(fig)
    log.info("figure %s written", fig_id)
