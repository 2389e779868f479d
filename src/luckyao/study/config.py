"""Study configuration: validation, case resolution, hashing and the turbulence key.

A study config (YAML) has a ``base`` system and named ``cases`` that override
it. Everything is checked against ``config.schema.yaml`` (beside this module) and a
few cross-key rules before any job runs; the first problem is reported as a
``ConfigError`` naming the key (``cases.noao_r0_20cm.atmosphere.r0_500nm_m``).
"""

import copy
import functools
import hashlib
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import yaml

SCHEMA_PATH = Path(__file__).with_name("config.schema.yaml")


class ConfigError(ValueError):
    """A study configuration that breaks the schema or a cross-key rule."""


def load_schema(path: Path = SCHEMA_PATH) -> dict:
    """The config schema (a fresh copy: parsed once per process)."""
    return copy.deepcopy(_parsed_yaml(Path(path)))


@functools.cache
def _parsed_yaml(path: Path) -> dict:
    with open(path) as f:
        return yaml.load(f, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def deep_merge(base: dict, override: dict) -> dict:
    """A new dict: ``base`` with ``override`` applied recursively (lists are replaced)."""
    merged = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def _key_path(prefix: str, error: jsonschema.ValidationError) -> str:
    parts = [prefix] if prefix else []
    parts += [str(p) for p in error.absolute_path]
    if error.validator == "required":
        missing = error.message.split("'")[1]
        parts.append(missing)
    elif error.validator == "additionalProperties":
        extra = error.message.split("'")[1]
        parts.append(extra)
    return ".".join(parts) or "(top level)"


def _message(error: jsonschema.ValidationError) -> str:
    """The schema's message, or for a name (``definitions.name``) what a safe name is."""
    if error.validator == "pattern" and error.schema.get("description", "").startswith("a case, figure or detector"):
        return (f"{error.instance!r} is not a safe name (a letter or digit, then letters, digits, _ . + -; "
                "never '..'): names become file names and command-line words")
    return error.message


def _validate(instance, schema: dict, prefix: str) -> None:
    """Every schema violation of ``instance``, one line each, naming its key."""
    validator = jsonschema.Draft7Validator(schema)
    errors = sorted(validator.iter_errors(instance), key=lambda e: list(e.absolute_path))
    if errors:
        raise ConfigError("\n".join(f"config key '{_key_path(prefix, e)}': {_message(e)}" for e in errors))


def validate_block(config: dict, key: str, schema: dict) -> None:
    """Check one top-level block of a study config against its part of the schema."""
    if key in config:
        _validate(config[key], dict(schema["properties"][key], definitions=schema["definitions"]), key)


def _check_finite(value, where: str) -> None:
    """Reject NaN and infinities anywhere (YAML's ``.nan``, ``.inf`` are numbers to JSON schema)."""
    if isinstance(value, dict):
        for key, item in value.items():
            _check_finite(item, f"{where}.{key}" if where else str(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _check_finite(item, f"{where}[{i}]")
    elif isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"config key '{where}': {value} is not a finite number")


def _check_case(name: str, case: dict, turbulence: dict) -> None:
    where = f"cases.{name}"
    atm = case["atmosphere"]
    n = len(atm["height_m"])
    for key in ("cn2_fraction", "wind_speed_m_s", "wind_direction_deg"):
        if len(atm[key]) != n:
            raise ConfigError(f"config key '{where}.atmosphere.{key}': has {len(atm[key])} values, "
                              f"height_m has {n}")
    if abs(sum(atm["cn2_fraction"]) - 1) > 1e-3:
        raise ConfigError(f"config key '{where}.atmosphere.cn2_fraction': sums to "
                          f"{sum(atm['cn2_fraction']):.4f}, must sum to 1")
    if atm["r0_amplitude_m"] >= atm["r0_500nm_m"]:
        raise ConfigError(f"config key '{where}.atmosphere.r0_amplitude_m': must be below r0_500nm_m")
    steps = case["camera"]["frame_time_s"] / case["time_step_s"]
    if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
        raise ConfigError(f"config key '{where}.camera.frame_time_s': must be a whole number of time_step_s")
    if case["duration_s"] < case["camera"]["frame_time_s"]:
        raise ConfigError(f"config key '{where}.duration_s': shorter than one camera frame")
    if case["duration_s"] > turbulence["duration_s"] + 1e-9:
        raise ConfigError(f"config key '{where}.duration_s': {case['duration_s']} s exceeds "
                          f"turbulence.duration_s = {turbulence['duration_s']} s")
    tomo = case["tomography"]
    if len(tomo["layer_cn2_fraction"]) != len(tomo["layer_heights_m"]):
        raise ConfigError(f"config key '{where}.tomography.layer_cn2_fraction': has "
                          f"{len(tomo['layer_cn2_fraction'])} values, layer_heights_m has {len(tomo['layer_heights_m'])}")
    if case["lgs"]["enabled"] and steps % case["wfs"]["exposure_steps"]:
        raise ConfigError(f"config key '{where}.wfs.exposure_steps': must divide the {round(steps)} steps "
                          "of a camera frame")
    if case["ao"]["mode"] != "none":
        if not case["lgs"]["enabled"]:
            raise ConfigError(f"config key '{where}.ao.mode': {case['ao']['mode']} needs lgs.enabled: true")
        if case["ao"]["delay_steps"] < case["wfs"]["exposure_steps"]:
            raise ConfigError(f"config key '{where}.ao.delay_steps': a command cannot be applied before its "
                              f"exposure ends (at least wfs.exposure_steps = {case['wfs']['exposure_steps']})")
    if "apodisation" in case["ao"] and case["ao"]["mode"] == "none":
        raise ConfigError(f"config key '{where}.ao.apodisation': needs ao.mode ltao or glao (it is applied with "
                          "each exposure's DM command)")
    if case["telescope"]["obscuration_m"] >= case["telescope"]["diameter_m"]:
        raise ConfigError(f"config key '{where}.telescope.obscuration_m': must be below diameter_m")
    reference = case.get("reference_target")
    if reference is not None and reference >= len(case["targets_arcsec"]):
        raise ConfigError(f"config key '{where}.reference_target': {reference} is not the index of one of the "
                          f"{len(case['targets_arcsec'])} targets_arcsec")
    radius = turbulence["field_radius_arcsec"]
    for x, y in case["targets_arcsec"]:
        if (x * x + y * y) ** 0.5 > radius:
            raise ConfigError(f"config key '{where}.targets_arcsec': target ({x}, {y}) lies beyond "
                              f"turbulence.field_radius_arcsec = {radius}")


def validate_study(config: dict, schema: dict | None = None) -> dict:
    """Check a study config; returns ``{case name: resolved case config}``.

    Raises ``ConfigError`` with one line per problem, each naming its key: every
    schema violation of the study, then the first problem of each case and of each
    figure.
    """
    from .scaling import derive_size_defaults
    from .sweeps import expand_sweeps

    schema = schema or load_schema()
    _check_finite(config, "")
    config = expand_sweeps(config)
    _validate(config, schema, "")
    case_schema = dict(schema["definitions"]["case"], definitions=schema["definitions"])
    cases, problems = {}, []
    for name, override in config["cases"].items():
        resolved = deep_merge(config["base"], override)
        try:
            _validate(resolved, case_schema, f"cases.{name}")
            resolved = derive_size_defaults(resolved, f"cases.{name}")
            _check_case(name, resolved, config["turbulence"])
            n_frames = frame_count(resolved)
            blocks = error_blocks(config["lucky"])
            if n_frames < 2 * blocks:
                raise ConfigError(f"config key 'lucky.error_blocks': {blocks} blocks need at least {2 * blocks} "
                                  f"frames, case '{name}' has {n_frames}")
        except ConfigError as err:
            problems.append(str(err))
            continue
        cases[name] = resolved
    for fig_id, figure in config["figures"].items():
        try:
            _check_figure(fig_id, figure, cases, config)
        except ConfigError as err:
            problems.append(str(err))
    if problems:
        raise ConfigError("\n".join(problems))
    return cases


def _check_figure(fig_id: str, figure: dict, cases: dict, config: dict) -> None:
    for case in figure["cases"]:
        if case not in config["cases"]:
            raise ConfigError(f"config key 'figures.{fig_id}.cases': unknown case '{case}'")
    needs = {"quality_vs_fraction": ("criteria",), "quality_vs_distance": ("criteria", "fractions"),
             "quality_vs_parameter": ("sweep", "criteria", "fractions"), "psf_gallery": ("criteria", "fractions"),
             "quality_vs_diameter": ("criteria", "fractions")}
    for key in needs.get(figure["kind"], ()):
        if key not in figure:
            raise ConfigError(f"config key 'figures.{fig_id}.{key}': required for {figure['kind']}")
    if "parameter" in figure and figure["parameter"] not in config["sweeps"][figure["sweep"]]["parameters"]:
        raise ConfigError(f"config key 'figures.{fig_id}.parameter': '{figure['parameter']}' is not a parameter "
                          f"of sweep '{figure['sweep']}'")
    if figure["kind"] == "comparisons":
        if "pairs" not in figure:
            raise ConfigError(f"config key 'figures.{fig_id}.pairs': required for comparisons")
        for i, pair in enumerate(figure["pairs"]):
            for side in ("a", "b"):
                case, criterion = pair[side]["case"], pair[side]["criterion"]
                if case not in figure["cases"]:
                    raise ConfigError(f"config key 'figures.{fig_id}.pairs[{i}].{side}.case': '{case}' is not "
                                      f"in the figure's cases")
                if case in cases and criterion not in criteria_of(cases[case]):
                    raise ConfigError(f"config key 'figures.{fig_id}.pairs[{i}].{side}.criterion': case '{case}' "
                                      f"cannot give {criterion}")
    if figure["kind"] == "quality_vs_distance":
        for case in figure["cases"]:
            if case in cases and len(cases[case]["targets_arcsec"]) < 2:
                raise ConfigError(f"config key 'figures.{fig_id}.cases': case '{case}' has one target; "
                                  "quality_vs_distance needs a field of targets")
    for case in figure["cases"]:
        if case not in cases:  # invalid itself: reported with the cases
            continue
        produced = criteria_of(cases[case])
        needed = set(figure.get("criteria", []))
        needed |= {"lgs_rms"} if figure["kind"] == "rms_truth" else set()
        needed |= {"lgs_residual_rms"} if figure["kind"] == "residuals" else set()
        if needed - produced:
            raise ConfigError(f"config key 'figures.{fig_id}.cases': case '{case}' cannot give "
                              f"{', '.join(sorted(needed - produced))} (needs "
                              f"{'LGS' if 'lgs_rms' in needed - produced else 'AO'})")
    detector = figure.get("detector")
    if detector is not None and detector not in config["lucky"]["detectors"]:
        raise ConfigError(f"config key 'figures.{fig_id}.detector': unknown detector '{detector}'")
    if figure["kind"] in SIGNAL_KINDS:
        kind = figure["kind"]
        sweep = config["lucky"].get("detector_sweep")
        if sweep is None:
            raise ConfigError(f"config key 'figures.{fig_id}.kind': {kind} needs lucky.detector_sweep")
        for key in ("criteria", "fractions", "read_noise_e") + (("metric",) if kind == "quality_vs_signal" else ()):
            if key not in figure:
                raise ConfigError(f"config key 'figures.{fig_id}.{key}': required for {kind}")
        missing = set(figure["read_noise_e"]) - set(sweep["read_noise_e"])
        if missing:
            raise ConfigError(f"config key 'figures.{fig_id}.read_noise_e': {sorted(missing)} not in "
                              "lucky.detector_sweep.read_noise_e")
    missing = set(figure.get("fractions", [])) - set(config["lucky"]["fractions"])
    if missing:
        raise ConfigError(f"config key 'figures.{fig_id}.fractions': {sorted(missing)} not in lucky.fractions")


PLAUSIBLE_RANGES = (
    ("atmosphere.r0_500nm_m", 0.02, 2.0, "m", "a Fried parameter at 500 nm (10 cm is 0.10)"),
    ("atmosphere.outer_scale_m", 1.0, 1000.0, "m", "an outer scale"),
    ("camera.wavelength_m", 3e-7, 3e-6, "m", "a science wavelength (0.3-3 um)"),
    ("lgs.wavelength_m", 3e-7, 3e-6, "m", "a laser wavelength (0.3-3 um)"),
    ("lgs.height_m", 5e3, 200e3, "m", "a beacon height"),
    ("telescope.diameter_m", 0.1, 100.0, "m", "a telescope diameter"),
    ("duration_s", 0.0, 3600.0, "s", "telescope time per case"),
    ("camera.frame_time_s", 1e-4, 1.0, "s", "a lucky frame's exposure"),
)
"""(key path of a case, lowest and highest plausible value, unit, what it is): values
outside are allowed but warned about (a unit slip, e.g. r0 in cm written as metres)."""


def plausibility_warnings(cases: dict) -> list[str]:
    """One line per value of a resolved case outside :data:`PLAUSIBLE_RANGES` or a wind
    speed above 100 m/s, naming the key; the config stays valid."""
    lines = []
    for name, case in cases.items():
        for path, low, high, unit, what in PLAUSIBLE_RANGES:
            value = case
            for part in path.split("."):
                value = value[part]
            if not low <= value <= high:
                lines.append(f"config key 'cases.{name}.{path}': {value:g} {unit} is outside {low:g}-{high:g} "
                             f"{unit}, implausible for {what}; is the unit right?")
        fastest = max(case["atmosphere"]["wind_speed_m_s"])
        if fastest > 100:
            lines.append(f"config key 'cases.{name}.atmosphere.wind_speed_m_s': {fastest:g} m/s is above 100 m/s")
    return lines


def unused_cases(config: dict) -> list[str]:
    """Cases that no figure lists (``all`` does not run them; ``all_cases`` does)."""
    shown = {case for figure in config["figures"].values() for case in figure["cases"]}
    return [name for name in config["cases"] if name not in shown]


def drawn_cases(config: dict) -> list[str]:
    """Cases whose results a figure reads (sweeps expanded), sorted: ``all`` runs them and
    exports their images; a finished study has every one's ``lucky.nc`` and ``telemetry.nc``
    (the asterism figure is geometry only: its cases are not run for it)."""
    return sorted({case for figure in config["figures"].values() if figure["kind"] != "asterism"
                   for case in figure["cases"]})


def frame_count(case: dict) -> int:
    """Whole lucky frames in a resolved case's duration."""
    return int(np.floor(case["duration_s"] / case["camera"]["frame_time_s"] + 1e-9))


def imaged_targets(case: dict) -> list[int]:
    """Indices of the targets a resolved case's simulation images and stores: every target,
    or with a ``reference_target`` and several targets only that one (the star); the
    others are replayed where they are post-processed, so a field's frames never all
    sit on disk."""
    reference, n_targets = case.get("reference_target"), len(case["targets_arcsec"])
    return list(range(n_targets)) if reference is None or n_targets == 1 else [reference]


def criteria_of(case: dict) -> set[str]:
    """Selection criteria a resolved case gives: image criteria always, ``lgs_rms`` with
    LGS, ``lgs_residual_rms`` and the oracle ``true_rms`` with AO."""
    criteria = {"strehl", "d50"}
    if case["lgs"]["enabled"]:
        criteria.add("lgs_rms")
    if case["ao"]["mode"] != "none":
        criteria |= {"lgs_residual_rms", "true_rms"}
    return criteria


def load_study(*paths) -> tuple[dict, dict]:
    """Read study YAML files, each deep-merged over the one before (as Snakemake's
    ``configfile:`` and ``--configfile`` do), and validate the result; returns
    (config as written, resolved cases: the sweeps' among them)."""
    config = {}
    for path in paths:
        try:
            with open(path) as f:
                layer = yaml.safe_load(f) or {}
        except FileNotFoundError as err:
            raise ConfigError(f"config file '{path}' not found") from err
        except yaml.YAMLError as err:
            raise ConfigError(f"config file '{path}' is not valid YAML: {err}") from err
        config = deep_merge(config, layer)
    return config, validate_study(config)


def canonical_json(value) -> str:
    """Key-sorted compact JSON: the text that is hashed and stored."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def sha256(value) -> str:
    return hashlib.sha256(canonical_json(value).encode()).hexdigest()


def turbulence_spec(study: dict, case: dict) -> dict:
    """Everything the shared screens depend on (not r0 or Cn2: those only scale them); the
    strips' width across the wind for this case's telescope (``scaling.screen_min_across_m``)."""
    from .scaling import screen_min_across_m

    atm = case["atmosphere"]
    turbulence = {key: value for key, value in study["turbulence"].items() if key != "min_across_diameters"}
    return {
        "seed": study["seed"],
        **turbulence,
        "min_across_m": screen_min_across_m(study["turbulence"], case["telescope"]["diameter_m"]),
        "time_step_s": case["time_step_s"],
        "diameter_m": case["telescope"]["diameter_m"],
        "outer_scale_m": atm["outer_scale_m"],
        "height_m": atm["height_m"],
        "wind_speed_m_s": atm["wind_speed_m_s"],
        "wind_direction_deg": atm["wind_direction_deg"],
    }


def turbulence_key(spec: dict) -> str:
    return "screens_" + sha256(spec)[:12]


def reconstructor_spec(case: dict) -> dict | None:
    """Everything a case's tomographic reconstructor depends on (None without LGS)."""
    if not case["lgs"]["enabled"]:
        return None
    return {key: case[key] for key in ("telescope", "lgs", "wfs", "tomography", "targets_arcsec")}


def reconstructor_key(spec: dict) -> str:
    return "reconstructor_" + sha256(spec)[:12]


def commands_spec(case: dict) -> dict | None:
    """Everything a case's AO command matrix depends on (None without AO): not the
    targets or the atmosphere, so cases that differ only there share it."""
    if case["ao"]["mode"] == "none":
        return None
    ao = {key: value for key, value in case["ao"].items() if key != "apodisation"}  # not in the commands
    return {**{key: case[key] for key in ("telescope", "lgs", "wfs", "tomography")}, "ao": ao}


def commands_key(spec: dict) -> str:
    return "commands_" + sha256(spec)[:12]


def calibration_spec(study: dict, case: dict) -> dict | None:
    """Everything a case's WFS calibration depends on (None without LGS or calibration):
    the sensor, its estimator and the seeing (the mean r0; not the winds, the noise or
    the exposure time, so cases that differ only there share it)."""
    wfs = case["wfs"]
    if not case["lgs"]["enabled"] or {**case_defaults("wfs"), **wfs}["calibration"] == "none":
        return None
    atm = case["atmosphere"]
    return {"seed": study["seed"], "telescope": case["telescope"], "lgs": case["lgs"],
            "wfs": {k: v for k, v in wfs.items() if k not in ("photons_per_subaperture", "read_noise_e", "exposure_steps")},
            "atmosphere": {k: atm[k] for k in ("r0_500nm_m", "outer_scale_m", "height_m", "cn2_fraction")}}


def calibration_key(spec: dict) -> str:
    return "calibration_" + sha256(spec)[:12]


def lgs_spec(case: dict) -> dict | None:
    """Everything of a resolved case that its LGS telemetry (each frame's ``lgs_rms``)
    depends on besides its screens and seed (None without LGS): the case less its AO (the
    sensor is open loop: it never sees the DM), its camera but the frame time, and its
    reference target."""
    if not case["lgs"]["enabled"]:
        return None
    spec = {key: value for key, value in case.items() if key not in ("ao", "camera", "reference_target")}
    return {**spec, "frame_time_s": case["camera"]["frame_time_s"]}


def lgs_chain_config(case: dict) -> dict:
    """A resolved case less its AO (the LGS sensor is open loop: it never sees the DM) and its
    targets, which its LGS slopes do not depend on; the rest makes a :class:`.case.Case`."""
    return {key: value for key, value in case.items() if key not in ("ao", "targets_arcsec", "reference_target")}


def slopes_spec(study: dict, case: dict) -> dict | None:
    """Everything an AO case's LGS slopes depend on (None without AO): its LGS chain, the
    seed and the screens; cases that differ only in their AO or targets share them."""
    if case["ao"]["mode"] == "none":
        return None
    return {"seed": study["seed"], "screens": turbulence_key(turbulence_spec(study, case)),
            "case": lgs_chain_config(case)}


def slopes_key(spec: dict) -> str:
    return "slopes_" + sha256(spec)[:12]


def lgs_twin(study: dict, cases: dict, name: str) -> str | None:
    """The case whose simulation measures a no-AO case's LGS telemetry, so that its own
    simulation images the science targets only: the first AO case (by name) with the same
    :func:`lgs_spec` and screens, whose simulation measures exactly the same slopes; None
    for a case with AO, without LGS, or with no such case."""
    case = cases[name]
    if case["ao"]["mode"] != "none" or (spec := lgs_spec(case)) is None:
        return None
    screens = turbulence_spec(study, case)
    return next((other for other in sorted(cases) if cases[other]["ao"]["mode"] != "none"
                 and lgs_spec(cases[other]) == spec and turbulence_spec(study, cases[other]) == screens), None)


def figure_default(key: str):
    """The schema's default of a figure key (``detector``: ``noiseless``)."""
    return load_schema()["properties"]["figures"]["additionalProperties"]["properties"][key]["default"]


SIGNAL_KINDS = ("quality_vs_signal", "registration")
"""The figure kinds drawn against the detector sweep: their cases get it and every registration method."""


def case_defaults(block: str) -> dict:
    """The schema's defaults of a case block's optional keys (``wfs``: ``centroider``,
    ``threshold``, ``calibration``, ...; ``telescope``: the size-scaling parameters): their one home."""
    keys = load_schema()["definitions"]["case"]["properties"][block]["properties"]
    return {key: spec["default"] for key, spec in keys.items() if "default" in spec}


def _lucky_value(lucky: dict, key: str):
    """``lucky[key]``, by default the schema's default of that key."""
    return lucky.get(key, load_schema()["properties"]["lucky"]["properties"][key]["default"])


def image_crop_px(lucky: dict) -> int | None:
    """Pixels across the images ``lucky.nc`` keeps: ``lucky.image_crop_px``, by default the
    schema's (64); None: the whole frame."""
    return _lucky_value(lucky, "image_crop_px")


def error_blocks(lucky: dict) -> int:
    """Time blocks for the Monte-Carlo errors: ``lucky.error_blocks``, by default the schema's."""
    return _lucky_value(lucky, "error_blocks")


def frame_strehl(lucky: dict) -> str:
    """How a frame's Strehl is measured: ``lucky.frame_strehl``, by default the schema's (``peak_pixel``)."""
    return _lucky_value(lucky, "frame_strehl")


def registrations(lucky: dict) -> list[str]:
    """The registration methods: ``lucky.registration``, by default the schema's (``cog`` only)."""
    return list(_lucky_value(lucky, "registration"))


def sweep_detectors(lucky: dict) -> dict:
    """The named detectors of ``lucky.detector_sweep`` (none without it): every read noise
    x ``levels`` photon counts per frame, log-spaced from ``min`` to ``max``."""
    sweep = lucky.get("detector_sweep")
    if sweep is None:
        return {}
    grid = sweep["photons_per_frame"]
    photons = np.geomspace(grid["min"], grid["max"], grid["levels"])
    return {sweep_name(read_noise, n): {"photons_per_frame": float(n), "read_noise_e": float(read_noise)}
            for read_noise in sweep["read_noise_e"] for n in photons}


def sweep_name(read_noise_e: float, photons_per_frame: float) -> str:
    return f"rn{read_noise_e:g}_{photons_per_frame:.3g}ph"


def lucky_settings(study: dict, cases: dict, case_name: str) -> dict:
    """The post-processing settings one case's lucky job uses, with its resolved config:
    every listed detector, and the detector sweep and every registration method when a
    ``quality_vs_signal`` or ``registration`` figure shows the case (their cost goes only where
    they are drawn; elsewhere ``cog`` alone)."""
    lucky = {key: value for key, value in study["lucky"].items() if key not in ("detector_sweep", "registration")}
    lucky["error_blocks"] = error_blocks(study["lucky"])
    lucky["registration"] = ["cog"]
    if any(f["kind"] in SIGNAL_KINDS and case_name in f["cases"] for f in study["figures"].values()):
        lucky["detectors"] = {**lucky["detectors"], **sweep_detectors(study["lucky"])}
        lucky["registration"] = registrations(study["lucky"])
    return {"seed": study["seed"], "case": case_name, "case_config": cases[case_name], **lucky}
