"""Overrides on the command line, MAOS-style: ``key.path=value`` words, each value a YAML scalar
or flow collection typed as YAML types it (``0.5`` a number, ``true`` a bool, ``[1, 2]`` a list,
``null`` none, ``ltao`` a string).

A path whose first part is a key of the study (``base.duration_s=0.5``,
``cases.my8m.telescope.diameter_m=8``, ``lucky.error_blocks=4``) sets that key; a path of a
case's keys (``telescope.diameter_m=8``) sets it in the case given with ``case=NAME`` (a new case,
an override of ``base``, when the study has none of that name). Snakemake's own ``--config``
gives nested values as strings: :func:`typed` types them at the edge (``Snakefile``).
"""

import yaml

from .schema import ConfigError, deep_merge, load_schema


def yaml_value(text: str):
    """A command-line value as YAML types it; text YAML cannot parse stays text."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError:
        return text


def typed(value):
    """A ``--config`` value with every string leaf typed as YAML (Snakemake reads nested
    values with YAML's base loader, as strings: ``{duration_s: 0.5}`` gives ``'0.5'``)."""
    if isinstance(value, dict):
        return {key: typed(item) for key, item in value.items()}
    if isinstance(value, list):
        return [typed(item) for item in value]
    return yaml_value(value) if isinstance(value, str) else value


def _nested(parts: list[str], value) -> dict:
    out = value
    for part in reversed(parts):
        out = {part: out}
    return out


def is_override(word: str) -> bool:
    """Whether a command-line word is a ``key=value`` override (not an option or a file)."""
    key = word.split("=", 1)[0]
    return "=" in word and not word.startswith("-") and "/" not in key and key != ""


def parse_overrides(words: list[str], case: str | None = None) -> dict:
    """The nested config of ``key.path=value`` words (:mod:`this module <.overrides>`); a case
    key's path goes under ``cases.<case>`` (a ``ConfigError`` without ``case``)."""
    study_keys = set(load_schema()["properties"])
    config = {}
    for word in words:
        if not is_override(word):
            raise ConfigError(f"override '{word}': not key.path=value")
        path, text = word.split("=", 1)
        parts = path.split(".")
        if any(not part for part in parts):
            raise ConfigError(f"override '{word}': an empty part in the key path '{path}'")
        if parts[0] not in study_keys:
            if case is None:
                raise ConfigError(
                    f"override '{word}': '{parts[0]}' is not a key of the study ({', '.join(sorted(study_keys))}); "
                    "a case's key needs case=NAME"
                )
            parts = ["cases", case, *parts]
        config = deep_merge(config, _nested(parts, yaml_value(text)))
    if case is not None:
        config = deep_merge({"cases": {case: {}}}, config)
    return config


def split_words(words: list[str]) -> tuple[str | None, list[str], list[str]]:
    """(the case of ``case=NAME``, the ``key=value`` overrides, the other words) of the
    leading words of a command line: overrides come before any option (``--cores 2``)."""
    case, overrides, index = None, [], 0
    while index < len(words) and is_override(words[index]):
        word = words[index]
        if word.startswith("case="):
            case = word.split("=", 1)[1]
        else:
            overrides.append(word)
        index += 1
    return case, overrides, words[index:]


def added_cases(study: dict, overlays: list[dict]) -> list[str]:
    """The cases the overlays (``--configfile`` files, ``--config``) add when they add cases and
    no figure or sweep: the default target runs these alone (and exports their FITS), not the
    whole study they were merged into; none otherwise."""
    if any("figures" in overlay or "sweeps" in overlay for overlay in overlays):
        return []
    names = {name for overlay in overlays for name in (overlay.get("cases") or {})}
    return sorted(name for name in names if name in study["cases"])
