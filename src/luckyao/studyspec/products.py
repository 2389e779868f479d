"""The cached products' specs: everything each product (screens, reconstructor, AO
command matrix, WFS calibration, LGS slopes) depends on, and its key (a hash of the spec),
so cases that share a product share its file."""

from ..io.hashing import sha256
from .scaling import screen_min_across_m
from .schema import case_defaults


def turbulence_spec(study: dict, case: dict, duration_s: float | None = None) -> dict:
    """Everything the shared screens depend on (not r0 or Cn2: those only scale them); the
    strips' width across the wind for this case's telescope (``scaling.screen_min_across_m``);
    their length ``duration_s``, by default ``turbulence.duration_s`` when the study pins it,
    else the case's own (:func:`screens_durations` gives each case the longest of the cases
    that share its screens)."""
    atm = case["atmosphere"]
    turbulence = {key: value for key, value in study["turbulence"].items() if key != "min_across_diameters"}
    if duration_s is None:
        duration_s = turbulence.get("duration_s", case["duration_s"])
    return {
        "seed": study["seed"],
        **turbulence,
        "duration_s": duration_s,
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


def screens_durations(study: dict, cases: dict) -> dict[str, float]:
    """``{case: length of its screens [s]}``: ``turbulence.duration_s`` when the study pins it,
    else the longest duration of the cases whose screens are otherwise the same (a 1 s case
    alone gets 1 s of screens; cases sharing screens get the longest one's)."""
    if "duration_s" in study["turbulence"]:
        return {name: study["turbulence"]["duration_s"] for name in cases}
    groups = {name: sha256(turbulence_spec(study, case, 0.0)) for name, case in cases.items()}
    longest = {}
    for name, group in groups.items():
        longest[group] = max(longest.get(group, 0.0), cases[name]["duration_s"])
    return {name: longest[group] for name, group in groups.items()}


def iterative(case: dict) -> bool:
    """Whether a resolved case's tomography is the iterative layer-space estimate, built in its
    simulation: then it has no dense reconstructor or command-matrix product."""
    return case["tomography"].get("method") == "iterative"


def geometric_wfs(case: dict) -> bool:
    """Whether a resolved case's LGS WFS is the geometric one (``wfs.model``): no calibration product."""
    return case["wfs"].get("model") == "geometric"


ITERATIVE_KEYS = frozenset(("method", "iterative_rtol"))
"""The tomography's keys that choose and tune its method (absent at their defaults: ``scaling.derived_case``)."""


SEEING_KEYS = ("r0_500nm_m", "outer_scale_m", "height_m", "cn2_fraction")
"""The atmosphere's keys of the seeing the beacons' spots see (the mean r0)."""


def seeing_spec(case: dict) -> dict:
    """The atmosphere block of the seeing the beacons' spots see (``case.seeing_from``)."""
    return {key: case["atmosphere"][key] for key in SEEING_KEYS}


def noise_seeing(case: dict) -> dict:
    """``{"atmosphere": seeing_spec}`` when the tomography weighs the slopes by the spots' NEA (a
    geometric WFS with photon noise: ``case.slope_noise_covariance_rad2``), else ``{}``."""
    if not geometric_wfs(case) or case["wfs"]["photons_per_subaperture"] is None:
        return {}
    return {"atmosphere": seeing_spec(case)}


def reconstructor_spec(case: dict) -> dict | None:
    """Everything a case's tomographic reconstructor depends on (None without LGS, or with the
    iterative tomography): with the slopes' NEA, the seeing of their spots too."""
    if not case["lgs"]["enabled"] or iterative(case):
        return None
    return {key: case[key] for key in ("telescope", "lgs", "wfs", "tomography", "targets_arcsec")} | noise_seeing(case)


def reconstructor_key(spec: dict) -> str:
    return "reconstructor_" + sha256(spec)[:12]


def commands_spec(case: dict) -> dict | None:
    """Everything a case's AO command matrix depends on (None without AO, or with the iterative
    tomography): not the targets or the atmosphere (but the seeing with the slopes' NEA:
    :func:`noise_seeing`), so cases that differ only there share it."""
    if case["ao"]["mode"] == "none" or iterative(case):
        return None
    not_in_commands = ("apodisation", "residual_budget", "laser_criteria", "learned_training_seed")
    ao = {key: value for key, value in case["ao"].items() if key not in not_in_commands}
    return {**{key: case[key] for key in ("telescope", "lgs", "wfs", "tomography")}, "ao": ao} | noise_seeing(case)


def commands_key(spec: dict) -> str:
    return "commands_" + sha256(spec)[:12]


def calibration_spec(study: dict, case: dict) -> dict | None:
    """Everything a case's WFS calibration depends on (None without LGS or calibration, or with the
    geometric WFS: the calibrated response is the physical-optics sensor's):
    the sensor, its estimator and the seeing (the mean r0; not the winds, the noise or
    the exposure time, so cases that differ only there share it)."""
    if not case["lgs"]["enabled"] or geometric_wfs(case):
        return None
    if {**case_defaults("wfs"), **case["wfs"]}["calibration"] == "none":
        return None
    return {
        "seed": study["seed"],
        "telescope": case["telescope"],
        "lgs": case["lgs"],
        "wfs": {
            k: v
            for k, v in case["wfs"].items()
            if k not in ("photons_per_subaperture", "read_noise_e", "exposure_steps")
        },
        "atmosphere": seeing_spec(case),
    }


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
    """A resolved case less its AO (the LGS sensor is open loop: it never sees the DM), its
    targets and its tomography's method, which its LGS slopes do not depend on (cases that differ
    only there share them); the rest makes a :class:`.case.Case`."""
    chain = {key: value for key, value in case.items() if key not in ("ao", "targets_arcsec", "reference_target")}
    if ITERATIVE_KEYS & case["tomography"].keys():
        tomography = {key: value for key, value in case["tomography"].items() if key not in ITERATIVE_KEYS}
        chain["tomography"] = tomography
    return chain


def slopes_spec(study: dict, case: dict, screens: dict | None = None) -> dict | None:
    """Everything an AO case's LGS slopes depend on (None without AO): its LGS chain, the
    seed and the screens (their spec, by default :func:`turbulence_spec`'s); cases that differ
    only in their AO or targets share them."""
    if case["ao"]["mode"] == "none":
        return None
    return {
        "seed": study["seed"],
        "screens": turbulence_key(screens or turbulence_spec(study, case)),
        "case": lgs_chain_config(case),
    }


def slopes_key(spec: dict) -> str:
    return "slopes_" + sha256(spec)[:12]


def lgs_twin(study: dict, cases: dict, name: str, screens: dict | None = None) -> str | None:
    """The case whose simulation measures a no-AO case's LGS telemetry, so that its own
    simulation images the science targets only: the first AO case (by name) with the same
    :func:`lgs_spec` and screens (``screens``: each case's screens spec, by default
    :func:`turbulence_spec`'s), whose simulation measures exactly the same slopes; None for a
    case with AO, without LGS, or with no such case."""
    case = cases[name]
    if case["ao"]["mode"] != "none" or (spec := lgs_spec(case)) is None:
        return None
    screens = screens or {other: turbulence_spec(study, cases[other]) for other in cases}
    return next(
        (
            other
            for other in sorted(cases)
            if cases[other]["ao"]["mode"] != "none"
            and lgs_spec(cases[other]) == spec
            and screens[other] == screens[name]
        ),
        None,
    )
