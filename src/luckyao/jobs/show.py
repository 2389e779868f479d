"""A case fully resolved, for ``luckyao show``: its keys (the derived ones named), what differs
from ``base``, the tomography prior, the screens, the products and its jobs' estimated time,
memory and files (:mod:`.resources`), as a dict (``--json``) or as text."""

from ..studyspec.scaling import DERIVED_KEYS, PRIOR_KEY
from ..studyspec.view import ResolvedStudy, flat
from .resources import screens_bytes, screens_samples, study_jobs


def case_report(view: ResolvedStudy, name: str) -> dict:
    """What ``luckyao show`` prints of case ``name`` of a resolved study."""
    case = view.cases[name]
    sources = {**DERIVED_KEYS, PRIOR_KEY: "atmosphere.r0_500nm_m"}
    prior = case.config["tomography"]["prior_r0_500nm_m"]
    jobs = [
        {
            "job": job.name,
            "time_s": round(job.seconds, 1),
            "memory_gb": round(job.memory_bytes / 1e9, 3),
            "file": job.output,
            "file_gb": round(job.output_bytes / 1e9, 3),
        }
        for job in study_jobs(view)
        if job.name in _jobs_of(view, name)
    ]
    return {
        "case": name,
        "config_sha256": case.config_sha256,
        "summary": summary_text(case.differences),
        "differences_from_base": case.differences,
        "derived": {path: {"value": value, "from": sources[path]} for path, value in case.derived.items()},
        "tomography_prior": {
            "r0_500nm_m": prior,
            "pinned": case.prior_pinned,
            "case_r0_500nm_m": case.config["atmosphere"]["r0_500nm_m"],
        },
        "screens": {
            "key": case.screens.key,
            "duration_s": case.screens.duration_s,
            "samples_per_layer": screens_samples(case.screens.spec),
            "file_gb": round(screens_bytes(case.screens.spec) / 1e9, 3),
        },
        "products": {kind: product.key for kind, product in case.products().items()},
        "lgs_twin": case.lgs_twin,
        "detectors": list(case.detectors),
        "registrations": list(case.registrations),
        "jobs": jobs,
        "config": flat(case.config),
    }


def _jobs_of(view: ResolvedStudy, name: str) -> set[str]:
    """The jobs the case's ``lucky.nc`` needs (its LGS twin's simulation and products too)."""
    case = view.cases[name]
    names = [name] + ([case.lgs_twin] if case.lgs_twin else [])
    jobs = {f"lucky {name}"}
    for other in names:
        jobs.add(f"simulate {other}")
        for kind, product in view.cases[other].products().items():
            jobs.add(f"{'turbulence' if kind == 'screens' else kind} {product.key}")
    return jobs


ASPECTS = {
    "ao.mode": lambda v: {"none": "no AO"}.get(v, str(v).upper()),
    "telescope.diameter_m": lambda v: f"{v:g} m telescope",
    "atmosphere.r0_500nm_m": lambda v: f"r0 {100 * v:g} cm",
    "lgs.n_beacons": lambda v: f"{v} LGS",
    "lgs.height_m": lambda v: f"LGS {v / 1e3:g} km",
    "wfs.n_subapertures": lambda v: f"{v}x{v} WFS",
    "ao.n_actuators": lambda v: f"{v}x{v} DM",
    "camera.n_pixels": lambda v: f"{v}-pixel camera",
    "duration_s": lambda v: f"{v:g} s",
    PRIOR_KEY: lambda v: f"prior r0 {100 * v:g} cm",
}
"""How ``summary_text`` writes the keys it knows; any other as ``key=value``."""


def summary_text(differences: dict) -> str:
    """Every key that differs from ``base``, in short: ``LTAO, 8 m telescope, 6 LGS, ...``."""
    known = [ASPECTS[path](differences[path]) for path in ASPECTS if path in differences]
    others = [f"{path}={value}" for path, value in differences.items() if path not in ASPECTS]
    return ", ".join(known + others) or "base"


def case_text(report: dict) -> str:
    """The report as readable text."""
    prior = report["tomography_prior"]
    screens = report["screens"]
    lines = [
        f"case {report['case']}: {report['summary']}",
        f"  config_sha256 {report['config_sha256'][:16]}",
        "derived (left out, so derived):",
        *(f"  {path} = {d['value']}   (from {d['from']})" for path, d in report["derived"].items()),
        f"tomography prior: r0 {prior['r0_500nm_m']} m, "
        + ("pinned" if prior["pinned"] else "following the case's r0")
        + (
            f" (the case's r0 is {prior['case_r0_500nm_m']} m)"
            if prior["r0_500nm_m"] != prior["case_r0_500nm_m"]
            else ""
        ),
        f"screens: {screens['key']}, {screens['duration_s']:g} s, {len(screens['samples_per_layer'])} layers, "
        f"{sum(screens['samples_per_layer']):,} samples, {screens['file_gb']:.3f} GB",
        "products: " + ", ".join(report["products"].values()),
        f"LGS twin: {report['lgs_twin'] or 'none'}",
        f"detectors: {', '.join(report['detectors'])}; registration: {', '.join(report['registrations'])}",
        "jobs (estimated time and memory; file written):",
        *(
            f"  {_job_text(job['job']):<40} {_duration(job['time_s']):>8} {job['memory_gb']:7.2f} GB"
            + (f"   {job['file']} {job['file_gb']:.3f} GB" if job["file"] else "")
            for job in report["jobs"]
        ),
        f"  {'all':<40} {_duration(sum(job['time_s'] for job in report['jobs'])):>8}",
        "resolved config:",
        *(f"  {path} = {value}" for path, value in report["config"].items()),
    ]
    return "\n".join(lines)


def _job_text(job: str) -> str:
    """A job as ``show`` writes it: a product's key alone where it names the step
    (``commands_2e6f...``, not ``commands commands_2e6f...``)."""
    step, _, what = job.partition(" ")
    return what if what.startswith(f"{step}_") else job


def _duration(seconds: float) -> str:
    """``42 s``, ``12.5 min`` or ``3.2 h``."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"
