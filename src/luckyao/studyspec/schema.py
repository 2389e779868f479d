"""The study configuration's schema (``schema.yaml`` beside this module) and checking a
config against it: every problem a ``ConfigError`` naming its key
(``cases.noao_r0_20cm.atmosphere.r0_500nm_m``). The schema is where optional keys' defaults live.
"""

import copy
import functools
import math
import re
from pathlib import Path

import jsonschema
import yaml

SCHEMA_PATH = Path(__file__).with_name("schema.yaml")


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
    if error.schema.get("description", "").startswith("a case, figure or detector"):
        problem = name_problem(error.instance)
        if problem is not None:
            return problem
    return error.message


def name_problem(name) -> str | None:
    """Why ``name`` cannot be a case, figure or detector name (``definitions.name`` of the
    schema: the whole name matched, printable ASCII, at most ``maxLength`` characters), or
    None when it can."""
    spec = _parsed_yaml(SCHEMA_PATH)["definitions"]["name"]
    if not isinstance(name, str):
        return f"{name!r} is not a name (a string)"
    if len(name) > spec["maxLength"]:
        return (
            f"'{name[:24]}...' is {len(name)} characters long, more than the {spec['maxLength']} a name may "
            "have: names become file names (255 bytes at most, with the workflow's suffixes)"
        )
    if not re.search(spec["pattern"], name):
        return (
            f"{name!r} is not a safe name (a letter or digit, then letters, digits, _ . + -; "
            "never '..'): names become file names and command-line words"
        )
    return None


def validate_keys(instance, schema: dict, prefix: str) -> None:
    """Every schema violation of ``instance``, one line each, naming its key."""
    validator = jsonschema.Draft7Validator(schema)
    errors = sorted(validator.iter_errors(instance), key=lambda e: list(e.absolute_path))
    if errors:
        raise ConfigError("\n".join(f"config key '{_key_path(prefix, e)}': {_message(e)}" for e in errors))


def validate_block(config: dict, key: str, schema: dict) -> None:
    """Check one top-level block of a study config against its part of the schema."""
    if key in config:
        validate_keys(config[key], dict(schema["properties"][key], definitions=schema["definitions"]), key)


def check_finite(value, where: str) -> None:
    """Reject NaN and infinities anywhere (YAML's ``.nan``, ``.inf`` are numbers to JSON schema)."""
    if isinstance(value, dict):
        for key, item in value.items():
            check_finite(item, f"{where}.{key}" if where else str(key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            check_finite(item, f"{where}[{i}]")
    elif isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(f"config key '{where}': {value} is not a finite number")


def figure_default(key: str):
    """The schema's default of a figure key (``detector``: ``noiseless``)."""
    return load_schema()["properties"]["figures"]["additionalProperties"]["properties"][key]["default"]


def case_defaults(block: str) -> dict:
    """The schema's defaults of a case block's optional keys (``wfs``: ``centroider``,
    ``threshold``, ``calibration``, ...; ``telescope``: the size-scaling parameters): their one home."""
    keys = load_schema()["definitions"]["case"]["properties"][block]["properties"]
    return {key: spec["default"] for key, spec in keys.items() if "default" in spec}


KEY_UNITS = (("_m_s", "m s-1"), ("_arcsec", "arcsec"), ("_nm", "nm"), ("_deg", "degree"), ("_m", "m"), ("_s", "s"))
"""A config key's units from its name's suffix (units in names: ``r0_500nm_m`` is in metres), in UDUNITS syntax."""


def key_units(key: str) -> str:
    """The UDUNITS units of a (dotted) config key's value (:data:`KEY_UNITS`); ``1`` for a number without units."""
    leaf = key.rsplit(".", 1)[-1]
    return next((units for suffix, units in KEY_UNITS if leaf.endswith(suffix)), "1")
