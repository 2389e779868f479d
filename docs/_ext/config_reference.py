"""The configuration reference, generated from the schema during the build.

``.. luckyao-config-reference::`` (in ``docs/configuration.rst``) becomes one section per
block of the study config, each a table of its keys: type (with its bounds), unit (the
``[...]`` of the description), default (the schema's, else the value in
``config/config.yaml``, the default study, marked so), whether it is required, and the
description. Nothing generated is checked in: the page is made from the schema at every
build, so it cannot drift from it.
"""

import re
from pathlib import Path

import yaml
from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles

REPO = Path(__file__).resolve().parents[2]
SCHEMA_PATH = REPO / "src" / "luckyao" / "studyspec" / "schema.yaml"
"""The study config's JSON schema (the one place keys, types, defaults and descriptions live)."""
DEFAULT_CONFIG = REPO / "config" / "config.yaml"
"""The default study, whose values stand in where the schema has no default."""

UNIT = re.compile(r"(?:^|(?<=\s))\[([^\[\]]+)\]")
IDENTIFIER = re.compile(r"(?<![\w`.])((?:[A-Za-z<][\w<>+-]*)(?:(?:\.|_|/)[\w<>*+-]+)+/?(?:\.\.\.)?)")
SPECIAL = re.compile(r"([\\*`_|])")

# the sections of the page: (title, key path in the config, schema node path, intro)
SECTIONS = [
    ("Top level", "", ("",), "The study's seed and whether frame cubes are kept."),
    ("turbulence", "turbulence", ("properties", "turbulence"), None),
    ("lucky", "lucky", ("properties", "lucky"), None),
    (
        "lucky.detectors.<name>",
        "lucky.detectors.<name>",
        ("properties", "lucky", "properties", "detectors", "additionalProperties"),
        None,
    ),
    ("lucky.detector_sweep", "lucky.detector_sweep", ("properties", "lucky", "properties", "detector_sweep"), None),
    (
        "base: the case",
        "base",
        ("definitions", "case"),
        "``base`` is the system every case starts from; a case of ``cases`` (and a point of a sweep) "
        "overrides any of these keys.",
    ),
    ("base.telescope", "base.telescope", ("definitions", "case", "properties", "telescope"), None),
    ("base.atmosphere", "base.atmosphere", ("definitions", "case", "properties", "atmosphere"), None),
    (
        "base.atmosphere.layer_variability",
        "base.atmosphere.layer_variability",
        ("definitions", "case", "properties", "atmosphere", "properties", "layer_variability"),
        None,
    ),
    ("base.camera", "base.camera", ("definitions", "case", "properties", "camera"), None),
    ("base.ao", "base.ao", ("definitions", "case", "properties", "ao"), None),
    (
        "base.ao.apodisation",
        "base.ao.apodisation",
        ("definitions", "case", "properties", "ao", "properties", "apodisation"),
        None,
    ),
    ("base.lgs", "base.lgs", ("definitions", "case", "properties", "lgs"), None),
    ("base.wfs", "base.wfs", ("definitions", "case", "properties", "wfs"), None),
    ("base.tomography", "base.tomography", ("definitions", "case", "properties", "tomography"), None),
    ("cases", "cases", ("properties", "cases"), None),
    ("sweeps.<name>", "sweeps.<name>", ("properties", "sweeps", "additionalProperties"), None),
    ("figures.<id>", "figures.<id>", ("properties", "figures", "additionalProperties"), None),
    (
        "figures.<id>.pairs[]",
        "figures.<id>.pairs[]",
        ("properties", "figures", "additionalProperties", "properties", "pairs", "items"),
        None,
    ),
    ("selection (a pair's a and b)", "selection", ("definitions", "selection"), None),
]
NESTED = {
    "turbulence": "turbulence",
    "lucky": "lucky",
    "lucky.detectors": "lucky.detectors.<name>",
    "lucky.detector_sweep": "lucky.detector_sweep",
    "base": "base",
    "cases": "cases",
    "base.telescope": "base.telescope",
    "base.atmosphere": "base.atmosphere",
    "base.atmosphere.layer_variability": "base.atmosphere.layer_variability",
    "base.camera": "base.camera",
    "base.ao": "base.ao",
    "base.ao.apodisation": "base.ao.apodisation",
    "base.lgs": "base.lgs",
    "base.wfs": "base.wfs",
    "base.tomography": "base.tomography",
    "sweeps": "sweeps.<name>",
    "figures": "figures.<id>",
    "figures.<id>.pairs": "figures.<id>.pairs[]",
    "figures.<id>.pairs[].a": "selection",
    "figures.<id>.pairs[].b": "selection",
}
"""Keys that have a section of their own: the section their row points to."""


def _node(schema: dict, path: tuple) -> dict:
    node = schema
    for part in path:
        if part:
            node = node[part]
    return node


def _resolve(schema: dict, node: dict) -> dict:
    """A node with its ``$ref`` followed (its own description wins)."""
    if "$ref" not in node:
        return node
    target = _node(schema, tuple(node["$ref"].lstrip("#/").split("/")))
    return {**target, **{k: v for k, v in node.items() if k != "$ref"}}


def _bounds(node: dict) -> str:
    parts = []
    for key, sign in (("exclusiveMinimum", ">"), ("minimum", "≥"), ("exclusiveMaximum", "<"), ("maximum", "≤")):
        if key in node:
            parts.append(f"{sign} {node[key]:g}")
    return ", ".join(parts)


def type_text(schema: dict, node: dict) -> str:
    """``number > 0``, ``list of number``, ``one of: none, ltao, glao``, ``mapping of <name> to object``."""
    node = _resolve(schema, node)
    if "enum" in node:
        return "one of: " + ", ".join(_literal(v) for v in node["enum"])
    kind = node.get("type", "any")
    if isinstance(kind, list):
        text = " or ".join("null" if k == "null" else k for k in kind)
    elif kind == "array":
        items = node.get("items", {})
        text = "list of " + (type_text(schema, items) if items else "any")
        if node.get("minItems") and node.get("minItems") == node.get("maxItems"):
            text = f"{node['minItems']} × " + type_text(schema, items)
        return text
    elif kind == "object" and isinstance(node.get("additionalProperties"), dict) and not node.get("properties"):
        text = "mapping of names to " + type_text(schema, node["additionalProperties"])
    else:
        text = kind
    bounds = _bounds(node)
    return f"{text} {bounds}" if bounds else text


def _literal(value) -> str:
    if value is None:
        return "``null``"
    if isinstance(value, bool):
        return f"``{str(value).lower()}``"
    if isinstance(value, float):
        return f"``{value:g}``"
    if isinstance(value, (list, dict)):
        text = yaml.safe_dump(value, default_flow_style=True, width=10_000).strip()
        return f"``{text}``"
    return f"``{value}``"


def _rst_text(text: str) -> str:
    """Prose from the schema as RST: identifiers (``lucky.nc``, ``diameter_m``) literal, the
    rest escaped so that no character of it is taken as markup."""
    out, last = [], 0
    for match in IDENTIFIER.finditer(text):
        out.append(SPECIAL.sub(r"\\\1", text[last : match.start()]))
        out.append(f"``{match.group(1)}``")
        last = match.end()
    out.append(SPECIAL.sub(r"\\\1", text[last:]))
    return "".join(out)


def split_unit(description: str) -> tuple[str, str]:
    """The description without its ``[unit]`` and the unit ('' when it has none)."""
    match = UNIT.search(description)
    if not match:
        return description, ""
    text = (description[: match.start()].rstrip() + description[match.end() :]).strip()
    return text, match.group(1)


def default_study_value(config: dict, key_path: str):
    """The key's value in ``config/config.yaml`` (``KeyError`` when it has none there)."""
    if "<" in key_path or key_path.startswith("cases"):
        raise KeyError(key_path)
    node = config
    for part in key_path.split("."):
        node = node[part]
    return node


def key_rows(schema: dict, config: dict, prefix: str, node: dict) -> list[tuple[str, str, str, str, str]]:
    """One row per key of a block: key, type, unit, default (and whether it is required), description."""
    rows = []  # (key, type, unit, default, description)
    required = set(node.get("required", ()))
    for key, child in node.get("properties", {}).items():
        path = f"{prefix}.{key}" if prefix else key
        child = _resolve(schema, child)
        description, unit = split_unit(" ".join(str(child.get("description", "")).split()))
        if "default" in child:
            default = _literal(child["default"])
        elif path in NESTED:
            default = "see its section"
        else:
            try:
                default = _literal(default_study_value(config, path)) + " (default study value)"
            except (KeyError, TypeError):
                default = "derived (see description)" if "default:" in description else "—"
        if key in required and "default" not in child:
            default = "required" if default == "—" else default + "; required"
        text = _rst_text(description)
        if path in NESTED:
            text = (text.rstrip(".") + ". " if text else "") + f"See :ref:`config-{_anchor(NESTED[path])}`."
        rows.append((f"``{key}``", type_text(schema, child), _rst_text(unit), default, text))
    return rows


def _anchor(path: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", path.lower()).strip("-") or "top-level"


def reference_rst(schema: dict, config: dict) -> list[str]:
    lines = []
    for title, key_path, node_path, intro in SECTIONS:
        node = _resolve(schema, _node(schema, node_path))
        lines += [f".. _config-{_anchor(key_path)}:", "", title, "-" * (len(title) + 4), ""]
        if intro:
            lines += [intro, ""]
        if node.get("description") and key_path:
            lines += [_capitalised(_rst_text(" ".join(str(node["description"]).split()))) + ".", ""]
        rows = key_rows(schema, config, key_path, node)
        if not rows:
            if key_path == "cases":
                lines += ["Each value is a mapping of the keys of :ref:`config-base` (only those that differ).", ""]
            continue
        lines += [
            ".. list-table::",
            "   :header-rows: 1",
            "   :widths: 17 15 9 17 42",
            "   :class: config-table",
            "",
            "   * - key",
            "     - type",
            "     - unit",
            "     - default",
            "     - description",
        ]
        for row in rows:
            lines.append(f"   * - {row[0]}")
            lines += [f"     - {cell}" if cell else "     -" for cell in row[1:]]
        lines.append("")
    return lines


def _capitalised(text: str) -> str:
    return text[:1].upper() + text[1:] if text and not text.startswith("``") else text


class ConfigReference(SphinxDirective):
    """``.. luckyao-config-reference::``: every key of the study config, section by section."""

    has_content = False

    def run(self):
        self.env.note_dependency(str(SCHEMA_PATH))
        self.env.note_dependency(str(DEFAULT_CONFIG))
        with open(SCHEMA_PATH) as f:
            schema = yaml.safe_load(f)
        with open(DEFAULT_CONFIG) as f:
            config = yaml.safe_load(f)
        container = nodes.container()
        nested_parse_with_titles(
            self.state, StringList(reference_rst(schema, config), source=str(SCHEMA_PATH)), container
        )
        return container.children


def setup(app):
    app.add_directive("luckyao-config-reference", ConfigReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
