"""The PSF gallery: integrated images of chosen cases beside their long exposure, on one
logarithmic intensity scale in units of the diffraction-limited peak (so a pixel's value
is its share of a perfect image's peak, and an image's brightest pixel is its Strehl)."""

import numpy as np
import xarray as xr
from matplotlib.colors import LogNorm

from .settings import FigureSettings, case_coords
from .style import CRITERIA, new_figure

DYNAMIC_RANGE = 1e4
"""Decades shown below the brightest pixel of the gallery."""


def psf_gallery_data(settings: FigureSettings, datasets) -> xr.Dataset:
    """Per case (first target) and panel, the image over the diffraction-limited peak:
    the long exposure without recentring, then each criterion x fraction's integrated
    image (shift-and-add of the selected frames), with its Strehl."""
    panels, images, strehls = [], [], []
    for criterion in settings.criteria:
        for fraction in settings.fractions:
            panels.append(f"{CRITERIA.get(criterion, criterion)}, {100 * fraction:g} %")
    for ds in datasets:
        peak = float(ds.attrs["diffraction_limited_peak"])
        first = ds.isel(target=0).sel(detector=settings.detector)
        row = [first.long_exposure_image.sel(recentring="none").values / peak]
        row_strehl = [float(first.long_exposure_strehl.sel(recentring="none"))]
        for criterion in settings.criteria:
            for fraction in settings.fractions:
                cell = first.sel(criterion=criterion, fraction=fraction)
                row.append(cell.image.values / peak)
                row_strehl.append(float(cell.strehl))
        images.append(row)
        strehls.append(row_strehl)
    offsets = datasets[0].x.values
    scale = float(datasets[0].attrs["pixel_scale_arcsec"])
    return xr.Dataset(
        {
            "image": (
                ("case", "panel", "y", "x"),
                np.array(images, dtype=np.float32),
                {"units": "1", "long_name": "intensity over the diffraction-limited peak of the same flux"},
            ),
            "strehl": (
                ("case", "panel"),
                np.array(strehls),
                {"units": "1", "long_name": "Strehl ratio of the panel's image (of the whole frame)"},
            ),
        },
        coords={
            **case_coords(settings, datasets),
            "panel": ("panel", ["long exposure"] + panels, {"long_name": "image shown"}),
            "y": ("y", offsets * scale, {"units": "arcsec", "long_name": "offset from the axis"}),
            "x": ("x", offsets * scale, {"units": "arcsec", "long_name": "offset from the axis"}),
        },
        attrs={"detector": settings.detector, "pixel_scale_arcsec": scale},
    )


def draw_psf_gallery(ds: xr.Dataset, title: str):
    n_rows, n_cols = ds.sizes["case"], ds.sizes["panel"]
    fig = new_figure(2.6 * n_cols + 1.0, 2.6 * n_rows + 0.8)
    axes = fig.subplots(n_rows, n_cols, squeeze=False, sharex=True, sharey=True)
    top = float(ds.image.max())
    norm = LogNorm(vmin=top / DYNAMIC_RANGE, vmax=top)
    half = 0.5 * ds.attrs["pixel_scale_arcsec"]
    extent = (float(ds.x[0]) - half, float(ds.x[-1]) + half, float(ds.y[0]) - half, float(ds.y[-1]) + half)
    for r, case in enumerate(ds.case.values):
        for c, panel in enumerate(ds.panel.values):
            ax, cell = axes[r, c], ds.sel(case=case, panel=panel)
            shown = ax.imshow(
                np.clip(cell.image.values, norm.vmin, None),
                origin="lower",
                extent=extent,
                norm=norm,
                cmap="magma",
                interpolation="nearest",
            )
            ax.text(
                0.04, 0.95, f"Strehl {float(cell.strehl):.3f}", transform=ax.transAxes, color="w", fontsize=8, va="top"
            )
            if r == 0:
                ax.set_title(str(panel), fontsize=9)
            if c == 0:
                ax.set_ylabel(f"{cell.label.values}\n[arcsec]", fontsize=9)
            if r == n_rows - 1:
                ax.set_xlabel("[arcsec]")
    fig.colorbar(shown, ax=axes, shrink=0.8, label="intensity / diffraction-limited peak")
    fig.suptitle(f"{title}: long exposure and lucky images ({ds.attrs['detector']} detector, one log scale)")
    return fig
