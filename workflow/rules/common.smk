# Study config, validated once at the edge; lookups the rules share. No physics here.
import os
import re
import shlex
import sys

from luckyao.jobs.code_deps import step_sources
from luckyao.io.datasets import atomic_path
from luckyao.jobs.live_run import hold_shared
from luckyao.jobs.resources import (
    calibration_memory_bytes,
    calibration_minutes,
    StudyTooLarge,
    checked_study,
    commands_memory_bytes,
    lucky_memory_bytes,
    lucky_minutes,
    lucky_seconds,
    machine_memory_bytes,
    mem_mb,
    reconstructor_memory_bytes,
    screens_job_threads,
    screens_minutes,
    simulate_memory_bytes,
    simulate_minutes,
    simulate_seconds,
    slopes_minutes,
    slopes_seconds,
    slopes_memory_bytes,
    turbulence_memory_bytes,
)
from luckyao.io.hashing import canonical_json, sha256
from luckyao.photometry import config_with_defaults
from luckyao.studyspec.lucky import MAGNITUDE_KINDS, SIGNAL_KINDS, sweep_detectors
from luckyao.studyspec.overrides import added_cases, typed
from luckyao.studyspec.resolved import imaged_targets
from luckyao.studyspec.schema import ConfigError
from luckyao.studyspec.study import plausibility_warnings
from luckyao.studyspec.sweeps import sweep_points
from luckyao.threads import STUDY_JOB, shell_prefix

RUN_LOCK = hold_shared()  # this study folder is in use until this Snakemake exits (run.sh cleans up only when free)

# Before any job, the pre-flight `luckyao check` runs too (src/luckyao/jobs/resources.py): the
# config validated (a sweep's grid points become cases), every job's memory within this
# machine's (or --resources mem_mb=N, e.g. a cluster's nodes), the files not yet made within
# the free disk together.
GIVEN_MEM_MB = getattr(workflow.global_resources.get("mem_mb"), "value", None)  # a snakemake Resource
MEMORY_LIMIT_BYTES = max(machine_memory_bytes(), 1e6 * GIVEN_MEM_MB if isinstance(GIVEN_MEM_MB, (int, float)) else 0)
try:
    VIEW = checked_study(config, ".", MEMORY_LIMIT_BYTES, workflow.cores if isinstance(workflow.cores, int) else None)
except ConfigError as err:
    what = "study too large" if isinstance(err, StudyTooLarge) else "invalid study config"
    sys.exit("\n".join(f"luckyao: {what}: {problem}" for problem in str(err).splitlines()))
STUDY, CASES = VIEW.config, VIEW.configs  # the study (sweeps expanded); {case: resolved config}
for warning in plausibility_warnings(CASES):
    print(f"luckyao: warning: {warning}", file=sys.stderr)
ADDED_CASES = added_cases(STUDY, [*OVERLAYS, typed(dict(workflow.config_settings.config))])
"""The cases overlays add without a figure (studyspec.overrides.added_cases): `all` runs these alone."""
if VIEW.unused and not ADDED_CASES:
    # warned, not run: a case no figure shows would cost its simulation (minutes to an hour at
    # paper fidelity) for nothing drawn; `snakemake all_cases` runs every case on purpose
    print(
        f"luckyao: warning: no figure shows the cases {', '.join(VIEW.unused)}: they are not run "
        "(`all_cases` runs every case; `bash run.sh study case=NAME` one)",
        file=sys.stderr,
    )


def _products(kind):
    """``{case: product or None}`` and ``{key: spec}`` of a product kind of the resolved view."""
    of_case = {name: getattr(case, kind) for name, case in VIEW.cases.items()}
    return of_case, {p.key: p.spec for p in of_case.values() if p is not None}


TURBULENCE, TURBULENCE_BY_KEY = _products("screens")
RECONSTRUCTOR, RECONSTRUCTOR_BY_KEY = _products("reconstructor")
COMMANDS, COMMANDS_BY_KEY = _products("commands")
CALIBRATION, CALIBRATION_BY_KEY = _products("calibration")
SLOPES, SLOPES_BY_KEY = _products("slopes")
LGS_TWIN = {name: case.lgs_twin for name, case in VIEW.cases.items()}
SLOPES_CASES = {}
"""The AO cases whose simulations replay each LGS slopes product, by its key (the first one's
calibration and memory estimate serve the product: they share its LGS chain)."""
for _name, _product in SLOPES.items():
    if _product is not None:
        SLOPES_CASES.setdefault(_product.key, []).append(_name)
TRAINING = {name: case.training for name, case in VIEW.cases.items() if case.training is not None}
"""The training twins of the cases with a learned criterion (ao.learned_training_seed), by case:
their screens and LGS slopes are made by the rules turbulence and lgs_slopes (the latter with its
case's calibration: the same instrument)."""
for _name, _twin in TRAINING.items():
    TURBULENCE_BY_KEY[_twin.screens.key] = _twin.screens.spec
    SLOPES_BY_KEY[_twin.slopes.key] = _twin.slopes.spec
    SLOPES_CASES.setdefault(_twin.slopes.key, []).append(_name)
# every job on one thread (src/luckyao/threads.py) and marked as a job of the workflow
# (STUDY_JOB: it holds the study's run lock while it lives and may set a bad input of the
# study aside); every value formatted into a command is quoted (:q)
LUCKYAO = f"{STUDY_JOB}=1 {shell_prefix()}{shlex.quote(sys.executable)} -m luckyao"


def reconstructor_file(case):
    """The case's cached reconstructor file, or [] without LGS."""
    product = RECONSTRUCTOR[case]
    return product.path if product else []


def commands_file(case):
    """The case's cached AO command-matrix file, or [] without AO."""
    product = COMMANDS[case]
    return product.path if product else []


def calibration_file(case):
    """The case's cached WFS calibration file, or [] without one."""
    product = CALIBRATION[case]
    return product.path if product else []


def simulation_calibration(case):
    """The WFS calibration a case's simulation reads, or []: none with an LGS twin or with
    recorded slopes, unless its residual budget (ao.residual_budget) runs the sensor's
    noiseless twin."""
    if LGS_TWIN[case] or (SLOPES[case] and not CASES[case].get("ao", {}).get("residual_budget", False)):
        return []
    return calibration_file(case)


def learned_file(case):
    """The case's learned model (rule learned_model), or [] without ao.learned_training_seed."""
    return f"results/training/{case}/learned.nc" if case in TRAINING else []


def slopes_file(case):
    """The AO case's LGS slopes product (config.slopes_spec), or [] without AO."""
    product = SLOPES[case]
    return product.path if product else []


REPLAY_FRAMES = STUDY.get("replay_frames", False)
"""No frame cube: the simulation images nothing and the lucky job replays every target."""


def frames_output(path):
    """The simulation's frame cube as its output named ``frames`` (kept, or temporary), or none
    with ``replay_frames``."""
    if REPLAY_FRAMES:
        return {}
    return {"frames": path if STUDY.get("keep_frames", False) else temp(path)}


wildcard_constraints:
    case="|".join(re.escape(c) for c in CASES),
    key="screens_[0-9a-f]{12}",
    rkey="reconstructor_[0-9a-f]{12}",
    ckey="commands_[0-9a-f]{12}",
    skey="slopes_[0-9a-f]{12}",
    wkey="calibration_[0-9a-f]{12}",
    fig="|".join(re.escape(f) for f in STUDY["figures"]),


def figure_settings(fig):
    """The figure's config, its cases' resolved configs, the seed, and what some kinds need
    besides: the detector sweep's detectors, a sweep's grid points, the photometric scale."""
    figure = STUDY["figures"][fig]
    extra = {}
    if figure["kind"] in SIGNAL_KINDS:
        extra["sweep_detectors"] = sweep_detectors(STUDY["lucky"])
    if figure["kind"] in MAGNITUDE_KINDS:  # the magnitude scale: only these figures redrawn when it changes
        extra["photometry"] = config_with_defaults(STUDY.get("photometry"))
    if "sweep" in figure:
        # each point's values as (path, value) pairs: in the sweep's order (a dict's keys would be
        # sorted as text in the settings' canonical JSON, and the first parameter is the default x)
        extra["sweep_points"] = [[p.case, list(p.values.items())] for p in sweep_points(STUDY, figure["sweep"])]
    differences = {
        c: {k: v for k, v in VIEW.cases[c].differences.items() if k not in VIEW.cases[c].derived}
        for c in figure["cases"]
    }
    return {
        **figure,
        "seed": STUDY["seed"],
        "case_configs": {c: CASES[c] for c in figure["cases"]},
        "case_differences": differences,
        **extra,
    }


def figure_settings_file(fig):
    """The file that carries a figure's settings (its config, its cases' resolved configs, the
    seed) to its job, so that they are not a (report-visible, very long) parameter. Named by
    their hash and written here, while the workflow is parsed, when missing: new settings are
    a new input, so the figure is redrawn exactly when they change; a file is never
    rewritten, so a dry run of another config cannot change one a live run reads; and no job
    is spent on it (a rule with a run directive costs a Snakemake start-up, ~6 s, each)."""
    settings = figure_settings(fig)
    path = f"results/figures/settings/{fig}_{sha256(settings)[:12]}.json"
    if not os.path.exists(path):
        with atomic_path(path) as partial:
            partial.write_text(canonical_json(settings))
    return path


FIGURE_SETTINGS = {fig: figure_settings_file(fig) for fig in STUDY["figures"]}


def figure_cases(fig):
    """The cases whose lucky datasets a figure reads; none for the geometry-only asterism figure."""
    figure = STUDY["figures"][fig]
    return [] if figure["kind"] == "asterism" else list(figure["cases"])


def figure_inputs(fig):
    """The cases' lucky datasets (:func:`figure_cases`)."""
    return [f"results/cases/{c}/lucky.nc" for c in figure_cases(fig)]


DRAWN_CASES = VIEW.drawn
"""The cases whose results a figure reads: `all` runs them and exports their images as FITS."""


def kept_files(case):
    """Every file a finished case keeps in the study folder: its ``lucky.nc`` and what its
    simulation made and read (``simulation_files``). Targets of ``all``: Snakemake remakes a
    missing intermediate only when something asks for it, so without them a file set aside
    (``<name>.bad``) or deleted whose consumers' outputs are there would stay missing, and a
    case whose ``lucky.nc`` is gone would be "Nothing to be done"; with them the next run
    remakes it and reruns what depends on it."""
    return [f"results/cases/{case}/lucky.nc", *simulation_files(case)]


def simulation_files(case):
    """A case's ``telemetry.nc`` (and ``frames.nc`` when kept) and the kept products its
    simulation reads (the inputs of ``simulate``): screens, reconstructor, command
    matrix, calibration, LGS slopes and the calibration they were measured with, and its LGS
    twin's (the twin's own simulation files)."""
    twin = LGS_TWIN[case]
    screens = TURBULENCE[case]
    files = [f"results/cases/{case}/telemetry.nc", screens.samples_path, screens.path]
    if STUDY.get("keep_frames", False):
        files.append(f"results/cases/{case}/frames.nc")
    files += [] if twin else listify(reconstructor_file(case))
    files += listify(commands_file(case))
    files += listify(simulation_calibration(case))
    if SLOPES[case]:
        files += [slopes_file(case), *listify(calibration_file(SLOPES_CASES[SLOPES[case].key][0]))]
    if twin:
        files += simulation_files(twin)
    return files


def listify(value):
    """A file or [] as a list of files."""
    return value if isinstance(value, list) else [value]


def figure_caption_rst(fig):
    """The report caption of a figure (config text escaped: no markup from names)."""
    from luckyao.jobs.report import figure_caption

    return figure_caption(fig, STUDY["figures"][fig], STUDY, CASES)


def short_code_version(version):
    """``0.1.0 git <40 hex> +dirty`` as ``0.1.0 git <12 hex> +dirty``."""
    return " ".join(word[:12] if len(word) == 40 else word for word in version.split())


def figure_report_labels(fig, data):
    """The report's labels of a figure: what it is, and the provenance its dataset carries."""
    import xarray as xr

    with xr.open_dataset(data) as ds:
        attrs = dict(ds.attrs)
    figure = STUDY["figures"][fig]
    cases = figure["cases"]
    return {
        "figure": fig,
        "kind": figure["kind"],
        "cases": ", ".join(cases) if len(cases) <= 3 else f"{len(cases)}: {', '.join(cases[:2])}, ...",
        "config": str(attrs.get("config_sha256", "?"))[:12],
        "code version": short_code_version(str(attrs.get("code_version", "?"))),
    }


def chain_seconds(name):
    """A case's estimated work after its screens [s on one core]: its LGS slopes product, its
    simulation and its lucky job (jobs/resources.py)."""
    slopes = slopes_seconds(CASES[name]) if VIEW.cases[name].slopes is not None else 0.0
    return slopes + simulate_seconds(CASES[name], LGS_TWIN[name]) + lucky_seconds(VIEW.cases[name].lucky_settings)


CHAIN_SECONDS = {name: chain_seconds(name) for name in CASES}
"""Each case's :func:`chain_seconds`, estimated once when the workflow is read."""


def simulate_priority(case):
    """Scheduling priority of a case's simulation, 0-9 (below the lucky rule's 10): the longest
    chains of work first (:data:`CHAIN_SECONDS`: the detector sweep's long lucky jobs, the
    fields, the largest telescopes), so that they run beside the short cases instead of alone at
    the end of the study; an LGS twin (config.lgs_twin) as early as the no-AO cases that wait
    for it."""
    own = max(CHAIN_SECONDS[name] for name in CASES if name == case or LGS_TWIN[name] == case)
    return min(9, int(10 * own / max(CHAIN_SECONDS.values())))


def screens_priority(key):
    """A screens job's scheduling priority: that of the most urgent simulation using them (a
    training twin's: its case's)."""
    users = [name for name, screens in TURBULENCE.items() if screens.key == key]
    users += [name for name, twin in TRAINING.items() if twin.screens.key == key]
    return max(simulate_priority(name) for name in users)


def screens_threads(key):
    """A screens job's threads (``resources.screens_job_threads``)."""
    return screens_job_threads(TURBULENCE_BY_KEY[key], len(TURBULENCE_BY_KEY))


def slopes_priority(key):
    """A slopes product's scheduling priority: that of the most urgent simulation waiting for it."""
    return max(simulate_priority(case) for case in SLOPES_CASES[key])


def lucky_mem_mb(case):
    """Memory a case's lucky job may hold [MB]: its estimate as is (``resources.lucky_memory_bytes``:
    the partial sums from their layout; the paper sweep's 19 detectors, 4.7 GB measured with
    ``cog`` alone), at least 3 GB (a field's replay; its memory-mapped screens not counted).
    """
    return mem_mb(lucky_memory_bytes(VIEW.cases[case].lucky_settings), 3000, margin=1.0)


def replay_screens(case):
    """The screens (and metadata) when the case's lucky job replays targets its simulation
    did not image (a field with a reference star; every case with replay_frames), else none."""
    if not REPLAY_FRAMES and len(imaged_targets(CASES[case])) == len(CASES[case]["targets_arcsec"]):
        return []
    return [TURBULENCE[case].samples_path, TURBULENCE[case].path]
