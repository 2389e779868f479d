"""The Snakemake report's caption of each figure, as reStructuredText made safe: every
text that comes from the config (figure, case and detector names, labels) is escaped,
so that no name can add markup (a directive, a role, raw HTML) to ``report.html``."""

import re

from ..figures.settings import CaseSummary
from ..studyspec.case import Case

KINDS = {
    "quality_vs_fraction": "Integrated-image quality (Strehl ratio, FWHM, 50%-energy diameter) vs the fraction of "
    "frames selected, a row of panels per selection criterion, a colour and marker per case, a line "
    "style per AO mode; curves that coincide drawn once; dotted: the long exposure without recentring.",
    "quality_vs_parameter": "Integrated-image quality vs a swept parameter, a row per selection criterion, a colour "
    "per value of the sweep's other parameters, a line style per fraction selected.",
    "quality_vs_diameter": "Integrated-image Strehl ratio and 50%-energy diameter vs the telescope diameter, a row per "
    "selection criterion, a colour per AO mode and beacon height, a line style per fraction "
    "selected; and the probability of a lucky frame (short-exposure Strehl above a threshold), with its Wilson "
    "interval.",
    "limiting_magnitude": "The limiting I magnitude of the reference star vs the telescope diameter: the detector "
    "sweep's knees (90 % of the noiseless integrated Strehl; d50 within 10 %) through each case's aperture "
    "(100 Hz frames), a colour per AO mode and beacon height, a line style per registration method.",
    "quality_vs_signal": "Integrated-image quality vs detected photons per lucky frame (the detector sweep: Poisson "
    "photon noise and Gaussian read noise), a row per registration method and a column per read "
    "noise and fraction selected; the noiseless detector's value for reference; noise-dominated points (more than "
    "30 % off the same selection on the noiseless frames) are left out.",
    "registration": "Integrated-image Strehl ratio and 50%-energy diameter vs detected photons per lucky frame "
    "(the detector sweep) for every registration method (colour and marker), selection criterion "
    "(line style), metric (rows), case and read noise (columns), the top axis in I magnitude (4.2 m, 100 Hz); "
    "its dataset holds each curve's knee (luckyao knees).",
    "quality_vs_distance": "Integrated-image quality vs the target's off-axis distance in the field, a row per "
    "selection criterion, a colour per case and a line style per fraction selected.",
    "psf_gallery": "The images themselves: each case's long exposure beside its lucky images (shift-and-add of the "
    "selected frames), on one logarithmic scale in units of the diffraction-limited peak.",
    "comparisons": "Paired differences a - b of integrated-image quality vs fraction, with paired (shared "
    "turbulence) and unpaired Monte-Carlo errors.",
    "long_exposure_check": "Simulated long-exposure Strehl ratio (all frames, no recentring, with its Monte-Carlo "
    "error) beside the analytic value, telescope OTF times exp(-D/2).",
    "long_exposure_table": "A table of every case's long-exposure Strehl ratio (all frames) without and with "
    "recentring, each with its Monte-Carlo error (batch means over time blocks).",
    "asterism": "The LGS pupil footprints (cone effect) at several layer heights, with the fraction of the target's "
    "footprint they cover.",
    "rms_truth": "Per frame, the LGS-reconstructed tilt-removed rms along the target vs the true one, with their "
    "correlation.",
    "residuals": "Time series of the open-loop and pseudo-closed-loop reconstructed tilt-removed rms with the true "
    "corrected rms, and their correlations.",
}


def rst_text(value) -> str:
    """``value`` as reStructuredText that renders as exactly its characters: one line,
    every character that could start markup backslash-escaped."""
    text = " ".join(str(value).split())
    return re.sub(r"([^A-Za-z0-9 ])", r"\\\1", text)


def figure_caption(fig_id: str, figure: dict, study: dict, cases: dict) -> str:
    """The caption of one figure (reStructuredText): what it shows, its settings, each
    case in short; the provenance is added by the template from the figure's dataset."""
    settings = []
    if figure.get("sweep"):
        settings.append(
            f"sweep {rst_text(figure['sweep'])}"
            + (f" along {rst_text(figure['parameter'])}" if figure.get("parameter") else "")
        )
    if figure.get("criteria"):
        settings.append("selection by " + ", ".join(rst_text(c) for c in figure["criteria"]))
    if figure.get("fractions"):
        settings.append("fractions " + ", ".join(f"{100 * f:g} %" for f in figure["fractions"]))
    if figure["kind"] not in ("asterism", "rms_truth", "residuals", "quality_vs_signal", "registration"):
        settings.append(f"detector {rst_text(figure.get('detector', 'noiseless'))}")
    if figure.get("read_noise_e"):
        settings.append("read noise " + ", ".join(f"{r:g}" for r in figure["read_noise_e"]) + " e-")
    if figure.get("metric"):
        settings.append(f"metric {rst_text(figure['metric'])}")
    settings.append(f"seed {int(study['seed'])}")
    settings.append(f"{study['base']['duration_s']:g} s of telescope time per case unless it sets its own")
    lines = [
        f"Figure **{rst_text(fig_id)}** ({rst_text(figure['kind'])}). " + KINDS.get(figure["kind"], ""),
        "",
        f"**Settings**: {'; '.join(settings)}.",
        "",
        f"**Cases** ({len(figure['cases'])}):",
        "",
    ]
    for name in figure["cases"]:
        lines.append(f"- {rst_text(name)}: {rst_text(CaseSummary.of(name, Case.from_config(cases[name])).summary())}")
    return "\n".join(lines)
