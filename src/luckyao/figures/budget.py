"""The residual budget figure: where each case's true corrected residual comes from, and which
of its parts move with the frame's Strehl ratio (:mod:`luckyao.ao.budget`)."""

import numpy as np
import xarray as xr

from ..ao.budget import budget_statistics, first_corrected_frame
from .settings import FigureSettings, case_coords
from .style import colour, new_figure


def residual_budget_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per case (``ao.residual_budget``) and part, :func:`luckyao.ao.budget.budget_statistics`
    against the frame's recentred short-exposure Strehl ratio (``frame_recentred_strehl`` of
    the figure's detector, the first target), from each case's first frame wholly corrected."""
    stats = []
    for name, ds in zip(settings.cases, datasets):
        if "residual_cross_nm2" not in ds:
            raise ValueError(f"residual_budget figure: case {name} has no residual budget (ao.residual_budget: true)")
        strehl = ds["frame_recentred_strehl"].isel(target=0).sel(detector=settings.detector).values
        stats.append(budget_statistics(ds, strehl, from_frame=first_corrected_frame(settings.case(name))))
    return xr.concat(stats, dim="case").assign_coords(case_coords(settings, datasets))


def draw_residual_budget(ds: xr.Dataset, title: str):
    parts = list(ds.part.values)
    fig = new_figure(13, 4.2)
    axes = fig.subplots(1, 3)
    panels = (
        ("mean_variance_nm2", "mean variance [nm²]"),
        ("share_of_total_fluctuation", "share of the total's frame-to-frame variance"),
        ("strehl_correlation", "correlation with the frame's Strehl ratio"),
    )
    width = 0.8 / ds.sizes["case"]
    for ax, (name, label) in zip(axes, panels):
        for c, case in enumerate(ds.case.values):
            row = ds.sel(case=case)
            x = np.arange(len(parts)) + (c - (ds.sizes["case"] - 1) / 2) * width
            ax.bar(x, row[name].values, width, color=colour(int(row.colour)), label=str(row.label.values))
        ax.set_xticks(np.arange(len(parts)), [p.replace("_", " ") for p in parts], rotation=45, ha="right")
        ax.set_ylabel(label)
        ax.axhline(0, color="k", lw=0.6)
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{title}: the true residual along the target, part by part (tilt removed, at 500 nm)")
    return fig
