"""A study config: read (YAML files merged in order), validated and resolved into cases.

A study config has a ``base`` system and named ``cases`` that override it. Everything is
checked against the schema (``schema.yaml``) and a few cross-key rules before any job runs;
the first problem of each case and figure is reported as a ``ConfigError`` naming the key.
"""

from ..clock import frame_count
from .lucky import (
    MAX_SWEEP_DETECTORS,
    SIGNAL_KINDS,
    error_blocks,
    fourier_cases,
    fourier_fractions,
    sweep_cases,
    sweep_detector_list,
)
from .resolved import criteria_of
from .scaling import PRIOR_KEY, derived_case, seeded_case
from .schema import ConfigError, check_finite, deep_merge, load_schema, validate_keys
from .sweeps import expand_study
from .yamlfile import read_config_file


def _check_case(name: str, case: dict, turbulence: dict) -> None:
    where = f"cases.{name}"
    atm = case["atmosphere"]
    n = len(atm["height_m"])
    for key in ("cn2_fraction", "wind_speed_m_s", "wind_direction_deg"):
        if len(atm[key]) != n:
            raise ConfigError(f"config key '{where}.atmosphere.{key}': has {len(atm[key])} values, height_m has {n}")
    if abs(sum(atm["cn2_fraction"]) - 1) > 1e-3:
        raise ConfigError(
            f"config key '{where}.atmosphere.cn2_fraction': sums to {sum(atm['cn2_fraction']):.4f}, must sum to 1"
        )
    if atm["r0_amplitude_m"] >= atm["r0_500nm_m"]:
        raise ConfigError(f"config key '{where}.atmosphere.r0_amplitude_m': must be below r0_500nm_m")
    steps = case["camera"]["frame_time_s"] / case["time_step_s"]
    if abs(steps - round(steps)) > 1e-6 or round(steps) < 1:
        raise ConfigError(f"config key '{where}.camera.frame_time_s': must be a whole number of time_step_s")
    if case["duration_s"] < case["camera"]["frame_time_s"]:
        raise ConfigError(f"config key '{where}.duration_s': shorter than one camera frame")
    if "duration_s" in turbulence and case["duration_s"] > turbulence["duration_s"] + 1e-9:
        raise ConfigError(
            f"config key '{where}.duration_s': {case['duration_s']} s exceeds "
            f"turbulence.duration_s = {turbulence['duration_s']} s"
        )
    tomo = case["tomography"]
    if len(tomo["layer_cn2_fraction"]) != len(tomo["layer_heights_m"]):
        raise ConfigError(
            f"config key '{where}.tomography.layer_cn2_fraction': has "
            f"{len(tomo['layer_cn2_fraction'])} values, layer_heights_m has {len(tomo['layer_heights_m'])}"
        )
    if case["lgs"]["enabled"] and steps % case["wfs"]["exposure_steps"]:
        raise ConfigError(
            f"config key '{where}.wfs.exposure_steps': must divide the {round(steps)} steps of a camera frame"
        )
    if case["ao"]["mode"] != "none":
        if not case["lgs"]["enabled"]:
            raise ConfigError(f"config key '{where}.ao.mode': {case['ao']['mode']} needs lgs.enabled: true")
        if case["ao"]["delay_steps"] < case["wfs"]["exposure_steps"]:
            raise ConfigError(
                f"config key '{where}.ao.delay_steps': a command cannot be applied before its "
                f"exposure ends (at least wfs.exposure_steps = {case['wfs']['exposure_steps']})"
            )
    if "apodisation" in case["ao"] and case["ao"]["mode"] == "none":
        raise ConfigError(
            f"config key '{where}.ao.apodisation': needs ao.mode ltao or glao (it is applied with "
            "each exposure's DM command)"
        )
    if case["ao"].get("residual_budget") and case["ao"]["mode"] == "none":
        raise ConfigError(
            f"config key '{where}.ao.residual_budget': needs ao.mode ltao or glao (it splits the AO residual)"
        )
    if case["ao"].get("laser_criteria") and case["ao"]["mode"] == "none":
        raise ConfigError(
            f"config key '{where}.ao.laser_criteria': needs ao.mode ltao or glao (the criteria use the DM's "
            "fit and commands)"
        )
    if "learned_training_seed" in case["ao"] and not case["ao"].get("laser_criteria"):
        raise ConfigError(
            f"config key '{where}.ao.learned_training_seed': needs ao.laser_criteria: true (its features)"
        )
    if tomo.get("method") == "iterative":
        _check_iterative(where, case)
    if case["wfs"].get("model") == "geometric" and case["ao"].get("residual_budget"):
        raise ConfigError(
            f"config key '{where}.ao.residual_budget': needs wfs.model physical (its sensor part is the "
            "physical-optics sensor against the geometric mean gradient)"
        )
    if case["telescope"]["obscuration_m"] >= case["telescope"]["diameter_m"]:
        raise ConfigError(f"config key '{where}.telescope.obscuration_m': must be below diameter_m")
    reference = case.get("reference_target")
    if reference is not None and reference >= len(case["targets_arcsec"]):
        raise ConfigError(
            f"config key '{where}.reference_target': {reference} is not the index of one of the "
            f"{len(case['targets_arcsec'])} targets_arcsec"
        )
    if "stars" in case:
        _check_stars(where, case)
    radius = turbulence["field_radius_arcsec"]
    for x, y in case["targets_arcsec"]:
        if (x * x + y * y) ** 0.5 > radius:
            raise ConfigError(
                f"config key '{where}.targets_arcsec': target ({x}, {y}) lies beyond "
                f"turbulence.field_radius_arcsec = {radius}"
            )
    lgs = case["lgs"]
    if lgs["enabled"] and lgs["asterism_diameter_arcsec"] / 2 > radius:
        raise ConfigError(
            f"config key '{where}.lgs.asterism_diameter_arcsec': beacons {lgs['asterism_diameter_arcsec'] / 2:g}\" "
            f"off axis lie beyond turbulence.field_radius_arcsec = {radius} (the screens' field)"
        )


def _check_iterative(where: str, case: dict) -> None:
    """The iterative tomography builds no dense matrix: what needs one is refused, naming its key."""
    ao = case["ao"]
    needs_dense = [key for key in ("residual_budget", "laser_criteria") if ao.get(key)]
    if ao.get("apodisation", {}).get("driver") == "lgs":
        needs_dense.append("apodisation.driver")
    if needs_dense:
        raise ConfigError(
            f"config key '{where}.ao.{needs_dense[0]}': needs tomography.method dense (it uses the dense "
            "reconstructors or command matrix), the case has tomography.method: iterative"
        )


def _check_stars(where: str, case: dict) -> None:
    """A case's several stars: distinct targets, the brightest the reference target (flux ratio 1),
    a flux ratio each, a science target that is none of them, counts within their number."""
    stars, n_targets = case["stars"], len(case["targets_arcsec"])
    targets = stars["targets"]
    key = f"config key '{where}.stars"
    if any(t >= n_targets for t in targets + [stars["science_target"]]):
        raise ConfigError(f"{key}': targets and science_target must index the {n_targets} targets_arcsec")
    if len(set(targets)) != len(targets) or stars["science_target"] in targets:
        raise ConfigError(f"{key}.targets': must be distinct and exclude science_target {stars['science_target']}")
    if targets[0] != case.get("reference_target"):
        raise ConfigError(f"{key}.targets': the first (the brightest) must be reference_target")
    if len(stars["flux_ratio"]) != len(targets) or stars["flux_ratio"][0] != 1:
        raise ConfigError(f"{key}.flux_ratio': one per star, the first 1 (the brightest)")
    if any(case["targets_arcsec"][t] == case["targets_arcsec"][stars["science_target"]] for t in targets):
        raise ConfigError(f"{key}.targets': a star in the science target's direction (no anisoplanatism to weigh)")
    if max(stars["counts"]) > len(targets):
        raise ConfigError(f"{key}.counts': at most the {len(targets)} stars")


def validate_study(config: dict, schema: dict | None = None) -> dict:
    """Check a study config; returns ``{case name: resolved case config}``.

    Raises ``ConfigError`` with one line per problem, each naming its key: every
    schema violation of the study, then the first problem of each case and of each
    figure.
    """
    schema = schema or load_schema()
    check_finite(config, "")
    config = expand_study(config)
    validate_keys(config, schema, "")
    case_schema = dict(schema["definitions"]["case"], definitions=schema["definitions"])
    cases, problems = {}, []
    try:
        _check_detectors(config["lucky"])
    except ConfigError as err:
        problems.append(str(err))
    problems += [
        f"config key 'lucky.detector_sweep.cases': unknown case '{name}'"
        for name in sweep_cases(config["lucky"])
        if name not in config["cases"]
    ]
    for name, override in config["cases"].items():
        resolved = deep_merge(config["base"], override)
        try:
            validate_keys(resolved, case_schema, f"cases.{name}")
            resolved = seeded_case(derived_case(resolved, f"cases.{name}"), config["seed"])
            _check_case(name, resolved, config["turbulence"])
            n_frames = frame_count(resolved)
            blocks = error_blocks(config["lucky"])
            if n_frames < 2 * blocks:
                raise ConfigError(
                    f"config key 'lucky.error_blocks': {blocks} blocks need at least {2 * blocks} "
                    f"frames, case '{name}' has {n_frames}"
                )
        except ConfigError as err:
            problems.append(str(err))
            continue
        cases[name] = resolved
    problems += _replay_problems(config, cases)
    problems += [
        f"config key 'cases.{name}.ao.learned_training_seed': {config['seed']} is the study's seed: the "
        "learned criterion must be trained on another seed's run than the one it is scored on"
        for name, case in cases.items()
        if case["ao"].get("learned_training_seed") == config["seed"]
    ]
    problems += _fourier_problems(config, cases)
    if not any(d["photons_per_frame"] is None for d in config["lucky"]["detectors"].values()):
        problems += [
            f"config key 'cases.{name}.stars': needs a noiseless detector in lucky.detectors (each star's "
            "noise is measured against its noiseless positions)"
            for name, case in cases.items()
            if "stars" in case
        ]
    for fig_id, figure in config["figures"].items():
        try:
            _check_figure(fig_id, figure, cases, config)
        except ConfigError as err:
            problems.append(str(err))
    if problems:
        raise ConfigError("\n".join(problems))
    return cases


def _fourier_problems(config: dict, cases: dict) -> list[str]:
    """Fourier lucky imaging's cases: known, and without a reference target (not built for them)."""
    key = "config key 'lucky.fourier.cases'"
    return [
        f"{key}: unknown case '{name}'"
        if name not in config["cases"]
        else f"{key}: case '{name}' has a reference_target (Fourier lucky imaging selects on the frames themselves)"
        for name in fourier_cases(config["lucky"])
        if name not in config["cases"] or (name in cases and cases[name].get("reference_target") is not None)
    ]


def _check_fourier_figure(fig_id: str, figure: dict, config: dict) -> None:
    """A fourier figure's cases given Fourier lucky imaging at its fractions, its read noises the sweep's."""
    lucky = config["lucky"]
    for case in figure["cases"]:
        if case not in fourier_cases(lucky):
            raise ConfigError(
                f"config key 'lucky.fourier.cases': case '{case}' is not one, but the fourier figure '{fig_id}' "
                "draws its Fourier lucky imaging: add it there (or take it off the figure)"
            )
    missing = set(figure["fractions"]) - set(fourier_fractions(lucky))
    if missing:
        raise ConfigError(f"config key 'figures.{fig_id}.fractions': {sorted(missing)} not in lucky.fourier.fractions")
    sweep = lucky.get("detector_sweep")
    missing = set(figure.get("read_noise_e", ())) - set(sweep["read_noise_e"] if sweep else ())
    if missing:
        raise ConfigError(
            f"config key 'figures.{fig_id}.read_noise_e': {sorted(missing)} not in lucky.detector_sweep.read_noise_e"
        )


def _check_selection_power(fig_id: str, figure: dict, cases: dict, config: dict) -> None:
    """A selection_power figure's cases have the oracle (AO), and every frame is a fraction (S_all)."""
    for case in figure["cases"]:
        if case in cases and "true_rms" not in criteria_of(cases[case]):
            raise ConfigError(
                f"config key 'figures.{fig_id}.cases': case '{case}' has no oracle (true_rms: needs ao.mode ltao "
                "or glao), against whose lucky gain selection_power measures every criterion"
            )
    if 1.0 not in config["lucky"]["fractions"]:
        raise ConfigError(
            f"config key 'lucky.fractions': the selection_power figure '{fig_id}' needs 1.0 (every frame, S_all)"
        )


def _replay_problems(config: dict, cases: dict) -> list[str]:
    """``replay_frames`` keeps no cube, and cannot replay an adaptively apodised case
    (:class:`luckyao.steps.simulation.Replay`)."""
    if not config.get("replay_frames", False):
        return []
    if config.get("keep_frames", False):
        return ["config key 'replay_frames': with keep_frames: true there is a cube to read; set one of them false"]
    return [
        f"config key 'cases.{name}.ao.apodisation': an adaptively apodised case cannot be replayed "
        "(replay_frames: true): image it in the simulation (replay_frames: false)"
        for name, case in cases.items()
        if case["ao"].get("apodisation") is not None
    ]


def _check_detectors(lucky: dict) -> None:
    """Every detector one name: the detector sweep's generated names (``rn<read noise>_<photons>ph``)
    distinct, and none of them a name of ``lucky.detectors`` (a case given the sweep would
    silently get the sweep's detector under the listed one's name)."""
    sweep = lucky.get("detector_sweep")
    if sweep is None:
        return
    count = len(sweep["read_noise_e"]) * sweep["photons_per_frame"]["levels"]
    if count > MAX_SWEEP_DETECTORS:
        raise ConfigError(
            f"config key 'lucky.detector_sweep': {len(sweep['read_noise_e'])} read noises x "
            f"{sweep['photons_per_frame']['levels']} levels make {count:,} detectors, more than the "
            f"{MAX_SWEEP_DETECTORS:,} a study may hold (each one's partial sums held in every lucky job "
            "it applies to)"
        )
    seen = {}
    for name, spec in sweep_detector_list(lucky):
        if name in seen:
            key = "photons_per_frame" if seen[name]["read_noise_e"] == spec["read_noise_e"] else "read_noise_e"
            unit = "photons" if key == "photons_per_frame" else "e-"
            raise ConfigError(
                f"config key 'lucky.detector_sweep.{key}': two of its detectors would share the name "
                f"'{name}' ({seen[name][key]:.9g} and {spec[key]:.9g} {unit}; names keep 3 significant "
                "digits of the photons and 6 of the read noise): make its values differ more"
            )
        seen[name] = spec
        if name in lucky["detectors"]:
            raise ConfigError(
                f"config key 'lucky.detectors.{name}': the detector sweep names one of its detectors "
                f"'{name}' too ({spec['read_noise_e']:g} e-, {spec['photons_per_frame']:g} photons per "
                "frame); a case given the sweep would get that one under this name: rename it"
            )


def _check_label(label, where: str) -> None:
    """A label drawn by matplotlib: its math text (between ``$``) must parse, as the figure
    job would parse it (matplotlib loaded only for a label holding ``$``)."""
    if "$" not in label:
        return
    from matplotlib import cbook
    from matplotlib.mathtext import MathTextParser

    if not cbook.is_math_text(label):
        return
    try:
        MathTextParser("path").parse(label, 72)
    except ValueError as err:
        reason = [line.strip() for line in str(err).splitlines() if line.strip()][-1]
        raise ConfigError(
            f"config key '{where}': matplotlib cannot draw {label!r} ({reason}); write the text "
            r"between $ as matplotlib math text, or a literal $ as \$"
        ) from None


def _check_figure(fig_id: str, figure: dict, cases: dict, config: dict) -> None:
    for case in figure["cases"]:
        if case not in config["cases"]:
            raise ConfigError(f"config key 'figures.{fig_id}.cases': unknown case '{case}'")
    needs = {
        "quality_vs_fraction": ("criteria",),
        "quality_vs_distance": ("criteria", "fractions"),
        "quality_vs_parameter": ("sweep", "criteria", "fractions"),
        "psf_gallery": ("criteria", "fractions"),
        "quality_vs_diameter": ("criteria", "fractions"),
        "limiting_magnitude": ("criteria", "fractions"),
        "fourier": ("criteria", "fractions"),
        "selection_power": ("fractions",),
    }
    for key in needs.get(figure["kind"], ()):
        if key not in figure:
            raise ConfigError(f"config key 'figures.{fig_id}.{key}': required for {figure['kind']}")
    if "parameter" in figure and figure["parameter"] not in config["sweeps"][figure["sweep"]]["parameters"]:
        raise ConfigError(
            f"config key 'figures.{fig_id}.parameter': '{figure['parameter']}' is not a parameter "
            f"of sweep '{figure['sweep']}'"
        )
    if figure["kind"] == "fourier":
        _check_fourier_figure(fig_id, figure, config)
    if figure["kind"] == "comparisons":
        if "pairs" not in figure:
            raise ConfigError(f"config key 'figures.{fig_id}.pairs': required for comparisons")
        labels = [pair["label"] for pair in figure["pairs"]]
        for i, pair in enumerate(figure["pairs"]):
            _check_label(pair["label"], f"figures.{fig_id}.pairs[{i}].label")
            if labels.index(pair["label"]) != i:
                raise ConfigError(
                    f"config key 'figures.{fig_id}.pairs[{i}].label': {pair['label']!r} is also the "
                    f"label of pairs[{labels.index(pair['label'])}] (a label names one difference)"
                )
            for side in ("a", "b"):
                case, criterion = pair[side]["case"], pair[side]["criterion"]
                if case not in figure["cases"]:
                    raise ConfigError(
                        f"config key 'figures.{fig_id}.pairs[{i}].{side}.case': '{case}' is not in the figure's cases"
                    )
                if case in cases and criterion not in criteria_of(cases[case]):
                    raise ConfigError(
                        f"config key 'figures.{fig_id}.pairs[{i}].{side}.criterion': case '{case}' "
                        f"cannot give {criterion}"
                    )
    if figure["kind"] == "quality_vs_distance":
        for case in figure["cases"]:
            if case in cases and len(cases[case]["targets_arcsec"]) < 2:
                raise ConfigError(
                    f"config key 'figures.{fig_id}.cases': case '{case}' has one target; "
                    "quality_vs_distance needs a field of targets"
                )
    if figure["kind"] == "residual_budget":
        for case in figure["cases"]:
            if case in cases and not cases[case]["ao"].get("residual_budget", False):
                raise ConfigError(
                    f"config key 'figures.{fig_id}.cases': case '{case}' has no residual budget "
                    "(ao.residual_budget: true)"
                )
    if figure["kind"] == "selection_power":
        _check_selection_power(fig_id, figure, cases, config)
    if figure["kind"] == "more_stars":
        for case in figure["cases"]:
            if case in cases and "stars" not in cases[case]:
                raise ConfigError(
                    f"config key 'figures.{fig_id}.cases': case '{case}' has no stars (more_stars draws them)"
                )
    for case in figure["cases"]:
        if case not in cases:  # invalid itself: reported with the cases
            continue
        produced = criteria_of(cases[case])
        needed = set(figure.get("criteria", []))
        needed |= {"lgs_rms"} if figure["kind"] == "rms_truth" else set()
        needed |= {"lgs_residual_rms"} if figure["kind"] == "residuals" else set()
        if needed - produced:
            raise ConfigError(
                f"config key 'figures.{fig_id}.cases': case '{case}' cannot give "
                f"{', '.join(sorted(needed - produced))} (needs "
                f"{'LGS' if 'lgs_rms' in needed - produced else 'AO'})"
            )
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
        for case in figure["cases"]:
            if case not in sweep_cases(config["lucky"]):
                raise ConfigError(
                    f"config key 'lucky.detector_sweep.cases': case '{case}' is not one, but the {kind} "
                    f"figure '{fig_id}' draws its detector sweep: add it there (or take it off the figure)"
                )
        missing = set(figure["read_noise_e"]) - set(sweep["read_noise_e"])
        if missing:
            raise ConfigError(
                f"config key 'figures.{fig_id}.read_noise_e': {sorted(missing)} not in "
                "lucky.detector_sweep.read_noise_e"
            )
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
    speed above 100 m/s, naming the key, and one naming the LGS cases whose tomography prior
    is pinned to another r0 than theirs; the config stays valid."""
    lines = []
    for name, case in cases.items():
        for path, low, high, unit, what in PLAUSIBLE_RANGES:
            value = case
            for part in path.split("."):
                value = value[part]
            if not low <= value <= high:
                lines.append(
                    f"config key 'cases.{name}.{path}': {value:g} {unit} is outside {low:g}-{high:g} "
                    f"{unit}, implausible for {what}; is the unit right?"
                )
        fastest = max(case["atmosphere"]["wind_speed_m_s"])
        if fastest > 100:
            lines.append(f"config key 'cases.{name}.atmosphere.wind_speed_m_s': {fastest:g} m/s is above 100 m/s")
    pinned = [
        name
        for name, case in cases.items()
        if case["lgs"]["enabled"] and _prior_r0_m(case) != case["atmosphere"]["r0_500nm_m"]
    ]
    if pinned:
        lines.append(
            f"config key '{PRIOR_KEY}': pinned apart from the case's atmosphere.r0_500nm_m in the cases "
            f"{', '.join(pinned)} (the tomography's prior assumes other seeing than the case's; left out, "
            "it follows the case's r0)"
        )
    return lines


def _prior_r0_m(case: dict) -> float:
    return case["tomography"]["prior_r0_500nm_m"]


def unused_cases(config: dict) -> list[str]:
    """Cases that no figure lists (``all`` does not run them; ``all_cases`` does)."""
    shown = {case for figure in config["figures"].values() for case in figure["cases"]}
    return [name for name in config["cases"] if name not in shown]


def drawn_cases(config: dict) -> list[str]:
    """Cases whose results a figure reads (sweeps expanded), sorted: ``all`` runs them and
    exports their images; a finished study has every one's ``lucky.nc`` and ``telemetry.nc``
    (the asterism figure is geometry only: its cases are not run for it)."""
    return sorted(
        {case for figure in config["figures"].values() if figure["kind"] != "asterism" for case in figure["cases"]}
    )


def read_study(*paths) -> dict:
    """Study YAML files, each read strictly (``yamlfile``: no alias bombs, duplicate keys or
    top level other than a mapping) and deep-merged over the one before (as Snakemake's
    ``configfile:`` and ``--configfile`` do): the config as written, not yet validated."""
    config = {}
    for path in paths:
        config = deep_merge(config, read_config_file(path))
    return config


def load_study(*paths) -> tuple[dict, dict]:
    """:func:`read_study`, validated; returns (config as written, resolved cases: the
    sweeps' among them)."""
    config = read_study(*paths)
    return config, validate_study(config)
