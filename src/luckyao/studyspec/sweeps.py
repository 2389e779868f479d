"""Sweeps: a grid of config values expanded into named cases.

A study's ``sweeps`` block names grids over key paths of a case::

    sweeps:
      r0:
        overrides: {wfs: {n_subapertures: 8}}         # shared by every point (optional)
        parameters:
          atmosphere.r0_500nm_m: [0.10, 0.135, 0.20]
          ao.mode: [ltao, none]

Every combination of the values (the product, in the order written) is a case, an
override of ``base`` like any other, named by its values:
``r0_r0_500nm_m-0.1_mode-ltao`` (``<sweep>_<key>-<value>_...``, the key's last part,
or its whole path when two parameters share a last part). A point whose resolved
config (derived keys too) equals a case of ``cases`` is that case (it is not simulated twice). Adding
values adds cases and leaves the others' names and configs as they were, so only the
new ones run. A figure with ``sweep: r0`` draws every point of the grid.
"""

import copy
import fnmatch
import itertools
import math
from dataclasses import dataclass

from ..io.hashing import canonical_json
from .scaling import DERIVED_KEYS, PRIOR_KEY, derived_case
from .schema import ConfigError, deep_merge, name_problem

MAX_GRID_POINTS = 1000
"""Most grid points of all of a study's sweeps together: each is a case, with its simulation
and post-processing jobs (the paper's sweeps hold 11)."""


@dataclass(frozen=True)
class SweepPoint:
    """One grid point of a sweep: its case name and ``{key path: value}``."""

    case: str
    values: dict


def _value_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return f"{value:g}"
    return str(value)


def _labels(paths: list[str]) -> dict[str, str]:
    """Each key path's label in case names: its last part, or the path when ambiguous."""
    last = [p.rsplit(".", 1)[-1] for p in paths]
    return {p: (leaf if last.count(leaf) == 1 else p) for p, leaf in zip(paths, last)}


def _nested(path: str, value) -> dict:
    """``a.b.c`` and ``v`` as ``{a: {b: {c: v}}}``."""
    out = value
    for part in reversed(path.split(".")):
        out = {part: out}
    return out


def _check_path(base: dict, path: str, where: str) -> None:
    if path in DERIVED_KEYS or path in DERIVED_KEYS.values() or path == PRIOR_KEY:  # keys a case may leave out
        return
    node = base
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConfigError(f"config key '{where}': '{path}' is not a key of base (or of the sweep's overrides)")
        node = node[part]
    if isinstance(node, dict):
        raise ConfigError(f"config key '{where}': '{path}' is a block of base, not a value")


def sweep_points(config: dict, sweep: str) -> list[SweepPoint]:
    """The grid points of ``config['sweeps'][sweep]``, each with its case name (an
    existing case of ``cases`` when its resolved config is the same)."""
    spec = config["sweeps"][sweep]
    parameters = spec["parameters"]
    paths = list(parameters)
    swept = deep_merge(config["base"], spec.get("overrides", {}))  # a key the overrides add may be swept
    for path in paths:
        _check_path(swept, path, f"sweeps.{sweep}.parameters.{path}")
    labels = _labels(paths)
    existing = {}
    for name, override in config.get("cases", {}).items():
        existing.setdefault(_resolved_text(config["base"], override), name)
    points, named = [], {}
    for values in itertools.product(*(parameters[p] for p in paths)):
        override = copy.deepcopy(spec.get("overrides", {}))
        for path, value in zip(paths, values):
            override = deep_merge(override, _nested(path, value))
        name = "_".join([sweep] + [f"{labels[p]}-{_value_text(v)}" for p, v in zip(paths, values)])
        if (problem := name_problem(name)) is not None:
            raise ConfigError(
                f"config key 'sweeps.{sweep}.parameters': the grid point {_point_text(paths, values)} "
                f"would be a case named by its values, but {problem}"
            )
        if name in named:
            path = next((p for p, a, b in zip(paths, named[name], values) if repr(a) != repr(b)), paths[0])
            raise ConfigError(
                f"config key 'sweeps.{sweep}.parameters.{path}': the values "
                f"{named[name][paths.index(path)]!r} and {values[paths.index(path)]!r} would share the "
                f"case name '{name}' (names keep 6 significant digits); make them differ there or "
                "sweep one of them"
            )
        named[name] = values
        name = existing.get(_resolved_text(config["base"], override), name)
        points.append(SweepPoint(name, dict(zip(paths, values))))
    return points


def _resolved_text(base: dict, override: dict) -> str:
    """A case's resolved config as text (its derived keys too: a point that pins a key to the
    value the case derives is that case), or as merged when it does not resolve (its problem is
    reported with the cases)."""
    merged = deep_merge(base, override)
    try:
        return canonical_json(derived_case(merged, ""))
    except (ConfigError, KeyError, TypeError, AttributeError):
        return canonical_json(merged)


def _point_text(paths, values) -> str:
    return "(" + ", ".join(f"{p}: {v!r}" for p, v in zip(paths, values)) + ")"


def grid_size(spec: dict) -> int:
    """Points of a sweep's grid (its ``parameters``' values multiplied), counted, not listed."""
    return math.prod(len(values) for values in spec["parameters"].values())


def sweep_overrides(config: dict, sweep: str) -> dict:
    """``{case name: override of base}`` of a sweep's points that are not existing cases."""
    spec = config["sweeps"][sweep]
    out = {}
    for point in sweep_points(config, sweep):
        if point.case not in config.get("cases", {}):
            override = copy.deepcopy(spec.get("overrides", {}))
            for path, value in point.values.items():
                override = deep_merge(override, _nested(path, value))
            out[point.case] = override
    return out


def expand_study(config: dict) -> dict:
    """A copy of ``config`` with every sweep's points among its ``cases``, each figure with a
    ``sweep`` given that sweep's cases (in grid order) and each with ``cases_matching`` the
    cases it matches (:func:`match_figure_cases`). Expanding an expanded config changes nothing."""
    return match_figure_cases(_expand_sweeps(config))


def match_figure_cases(config: dict) -> dict:
    """``config`` with each figure's ``cases_matching`` (shell patterns, ``fnmatch``) added to its
    ``cases`` (and the key dropped): pattern by pattern, the matching cases in the order the
    config lists them, each once. A pattern that matches no case is refused, naming it.
    Overlays compose through it: ``noao_D*`` draws a later overlay's ``noao_D39m`` too."""
    figures = config.get("figures") or {}
    if not any(isinstance(f, dict) and "cases_matching" in f for f in figures.values()):
        return config
    expanded = copy.deepcopy(config)
    names = list(expanded.get("cases") or {})
    for fig_id, figure in expanded["figures"].items():
        if not isinstance(figure, dict) or "cases_matching" not in figure:
            continue
        patterns = figure["cases_matching"]
        if not isinstance(patterns, list) or not all(isinstance(p, str) and p for p in patterns):
            raise ConfigError(f"config key 'figures.{fig_id}.cases_matching': a list of case-name patterns")
        drawn = list(figure.get("cases") or [])
        for pattern in patterns:
            matched = [name for name in names if fnmatch.fnmatchcase(name, pattern)]
            if not matched:
                raise ConfigError(f"config key 'figures.{fig_id}.cases_matching': {pattern!r} matches no case")
            drawn += [name for name in matched if name not in drawn]
        figure["cases"] = drawn
        del figure["cases_matching"]  # the figure as if its cases were written out
    return expanded


def _expand_sweeps(config: dict) -> dict:
    sweeps = config.get("sweeps") or {}
    if not sweeps:
        return config
    from .schema import load_schema, validate_block  # the sweeps block is checked before it is used

    validate_block(config, "sweeps", load_schema())
    sizes = {sweep: grid_size(spec) for sweep, spec in sweeps.items()}
    if sum(sizes.values()) > MAX_GRID_POINTS:
        largest = max(sizes, key=sizes.get)
        shape = " x ".join(str(len(v)) for v in sweeps[largest]["parameters"].values())
        others = f"; {sum(sizes.values()):,} with the other sweeps" if len(sizes) > 1 else ""
        raise ConfigError(
            f"config key 'sweeps.{largest}.parameters': a grid of {sizes[largest]:,} points ({shape} "
            f"values{others}), more than the {MAX_GRID_POINTS:,} a study may hold: each point is a "
            "case, with its own simulation and post-processing jobs"
        )
    expanded = copy.deepcopy(config)
    for sweep in sweeps:
        for name, override in sweep_overrides(config, sweep).items():
            if name in expanded["cases"] and expanded["cases"][name] != override:
                raise ConfigError(f"config key 'sweeps.{sweep}': its case '{name}' is also a different case in cases")
            expanded["cases"][name] = override
    for fig_id, figure in (expanded.get("figures") or {}).items():
        if isinstance(figure, dict) and "sweep" in figure:
            if figure["sweep"] not in sweeps:
                raise ConfigError(f"config key 'figures.{fig_id}.sweep': unknown sweep '{figure['sweep']}'")
            figure["cases"] = [p.case for p in sweep_points(config, figure["sweep"])]
    return expanded
