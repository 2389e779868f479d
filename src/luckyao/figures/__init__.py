"""Figures of the study: each is a tidy dataset first, then a drawing of it.

``draw_figure`` builds the figure's dataset from the cases' ``lucky.nc`` files,
writes it as ``<prefix>.nc`` and draws ``<prefix>.pdf`` and ``<prefix>.png``
from that dataset alone, and ``<prefix>.html``, the PNG in a page (the report's view). Each kind is a pair (data,
drawing) in :data:`FIGURE_KINDS`;
the drawings use matplotlib's object API (no pyplot, no backend chosen at import) and
one colour-blind-safe palette (``style``).

Public objects, by module --
settings: FigureSettings, CaseSummary; quality: the quality_vs_fraction,
quality_vs_distance, quality_vs_parameter and comparisons kinds; diameter: quality_vs_diameter; limiting:
limiting_magnitude; more_stars: more_stars; signal:
quality_vs_signal; wavefront: asterism, rms_truth, residuals; tables:
long_exposure_check, long_exposure_table, long_exposure_markdown, value_with_error;
gallery: psf_gallery; fourier: fourier (Fourier lucky imaging against shift-and-add); budget:
residual_budget; selection: selection_power (the share of the oracle's lucky gain each criterion recovers).
"""

import base64
import html
import json
import logging
from pathlib import Path

from ..io.datasets import open_dataset, provenance, require_finite_lucky, write_dataset
from ..io.hashing import sha256
from .budget import draw_residual_budget, residual_budget_data
from .diameter import draw_quality_vs_diameter, quality_vs_diameter_data
from .fourier import draw_fourier, fourier_data
from .gallery import draw_psf_gallery, psf_gallery_data
from .limiting import draw_limiting_magnitude, limiting_magnitude_data
from .more_stars import draw_more_stars, more_stars_data
from .quality import (
    comparisons_data,
    draw_comparisons,
    draw_quality_vs_distance,
    draw_quality_vs_fraction,
    draw_quality_vs_parameter,
    quality_vs_distance_data,
    quality_vs_fraction_data,
    quality_vs_parameter_data,
)
from .registration import draw_registration, registration_data
from .selection import draw_selection_power, selection_power_data
from .settings import CaseSummary, FigureSettings
from .signal import draw_quality_vs_signal, quality_vs_signal_data
from .style import DPI
from .tables import (
    draw_long_exposure_check,
    draw_long_exposure_table,
    long_exposure_check_data,
    long_exposure_markdown,
    long_exposure_table_data,
    value_with_error,
)
from .wavefront import asterism_data, draw_asterism, draw_residuals, draw_rms_truth, residuals_data, rms_truth_data

log = logging.getLogger(__name__)

FIGURE_KINDS = {
    "asterism": (asterism_data, draw_asterism),
    "rms_truth": (rms_truth_data, draw_rms_truth),
    "quality_vs_fraction": (quality_vs_fraction_data, draw_quality_vs_fraction),
    "quality_vs_parameter": (quality_vs_parameter_data, draw_quality_vs_parameter),
    "quality_vs_diameter": (quality_vs_diameter_data, draw_quality_vs_diameter),
    "limiting_magnitude": (limiting_magnitude_data, draw_limiting_magnitude),
    "long_exposure_check": (long_exposure_check_data, draw_long_exposure_check),
    "long_exposure_table": (long_exposure_table_data, draw_long_exposure_table),
    "quality_vs_signal": (quality_vs_signal_data, draw_quality_vs_signal),
    "registration": (registration_data, draw_registration),
    "quality_vs_distance": (quality_vs_distance_data, draw_quality_vs_distance),
    "comparisons": (comparisons_data, draw_comparisons),
    "residuals": (residuals_data, draw_residuals),
    "psf_gallery": (psf_gallery_data, draw_psf_gallery),
    "fourier": (fourier_data, draw_fourier),
    "more_stars": (more_stars_data, draw_more_stars),
    "residual_budget": (residual_budget_data, draw_residual_budget),
    "selection_power": (selection_power_data, draw_selection_power),
}

REGISTRATION_KINDS = ("registration", "quality_vs_signal", "limiting_magnitude", "fourier", "more_stars")
"""The kinds drawn for every registration method; the others draw the baseline, ``cog``."""


def baseline_registration(ds):
    """A case's lucky dataset for the baseline registration, ``cog`` (every method's dataset has it)."""
    return ds.sel(registration="cog") if "registration" in ds.dims else ds


__all__ = ["FIGURE_KINDS", "CaseSummary", "FigureSettings", "draw_figure", "long_exposure_markdown", "value_with_error"]


def draw_figure(fig_id: str, settings: dict, lucky_paths, out_prefix: str) -> None:
    """Build, save and draw one figure from its cases' lucky datasets (in ``settings['cases']`` order;
    none for geometry-only kinds); ``settings['case_configs']`` holds the cases' resolved configs."""
    typed = FigureSettings.from_dict(settings)
    datasets = [open_dataset(path, "lucky") for path in lucky_paths]
    for path, ds in zip(lucky_paths, datasets):  # the rule lucky.nc is written with, checked again
        require_finite_lucky(ds, f"lucky file '{path}'")
    if typed.kind not in REGISTRATION_KINDS:
        datasets = [baseline_registration(ds) for ds in datasets]
    make_data, draw = FIGURE_KINDS[typed.kind]
    ds = make_data(typed, datasets)
    ds.attrs.update(provenance(f"luckyao figure {fig_id}", settings, typed.seed))
    ds.attrs["case_config_sha256"] = json.dumps({n: sha256(c) for n, c in typed.case_configs.items()})
    write_dataset(ds, f"{out_prefix}.nc", allow_nan=set(ds.data_vars))  # drawn data; inputs are checked
    fig = draw(open_dataset(f"{out_prefix}.nc", "figure data"), fig_id)
    for ext in ("pdf", "png"):
        fig.savefig(f"{out_prefix}.{ext}", dpi=DPI)
    Path(f"{out_prefix}.html").write_text(figure_page(fig_id, Path(f"{out_prefix}.png").read_bytes()))
    log.info("figure %s written", fig_id)


def figure_page(fig_id: str, png: bytes) -> str:
    """A one-image HTML page that shows the PNG at the width of the window (the report's
    view of a figure: its image viewer can show a PNG zero pixels wide)."""
    name = html.escape(fig_id)
    return (
        '<!DOCTYPE html><html><head><meta charset="utf-8"><title>' + name + "</title><style>body{margin:0}"
        'img{display:block;width:100%;height:auto}</style></head><body><img alt="' + name + '" '
        'src="data:image/png;base64,' + base64.b64encode(png).decode() + '"></body></html>\n'
    )
