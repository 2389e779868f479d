"""A study config file read strictly, before anything walks it.

YAML allows what a study config never needs and what would make every later step go
wrong quietly or hang: aliases that expand a 2 KB file into billions of values (an
"alias bomb": any walk of it, Snakemake's config merge or the schema check, never ends),
a key written twice (the last silently wins), and a top level that is not a mapping.
:func:`read_config_text` refuses each, naming the file (and the lines of a duplicate key),
after parsing the file into YAML's node graph and before building or walking any value.
"""

from pathlib import Path

import yaml

from .schema import ConfigError

MAX_VALUES = 100_000
"""Most values (scalars, lists and mappings, every alias counted as what it expands to) a
config file may hold: the paper's study, its sweeps written out, holds a few thousand."""

_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_MERGE = "tag:yaml.org,2002:merge"


class _StrictLoader(_Loader):
    """The safe loader, refusing a mapping key written twice (a ``<<`` merge's keys may be
    overridden, as YAML intends)."""

    name = "<config>"

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE:
                    continue
                key, line = self.construct_object(key_node, deep=True), key_node.start_mark.line + 1
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: the safe loader's own error follows
                    continue
                if first is not None:
                    raise ConfigError(
                        f"config file '{self.name}': key {key!r} is written twice in one mapping "
                        f"(lines {first} and {line}); YAML would keep the last silently"
                    )
                seen[key] = line
        return super().construct_mapping(node, deep)


def _expanded_size(root: yaml.Node, where: str) -> int:
    """Values of the node graph ``root`` with every alias expanded, counted without expanding
    it (each node once); a ConfigError past :data:`MAX_VALUES` or for an alias inside itself."""
    sizes, children, stack = {}, {}, [root]
    while stack:
        node = stack[-1]
        key = id(node)
        if key in sizes:
            stack.pop()
            continue
        if key not in children:
            kids = (
                [n for pair in node.value for n in pair]
                if isinstance(node, yaml.MappingNode)
                else list(node.value)
                if isinstance(node, yaml.SequenceNode)
                else []
            )
            children[key] = kids
            pending = [kid for kid in kids if id(kid) not in sizes]
            for kid in pending:
                if id(kid) in children:  # on the path being walked: an alias inside its own anchor
                    raise ConfigError(
                        f"config file '{where}': a YAML alias refers to a value that holds it "
                        f"(line {kid.start_mark.line + 1}); a config is a tree"
                    )
            if pending:
                stack.extend(pending)
                continue
        sizes[key] = 1 + sum(sizes[id(kid)] for kid in children.pop(key))
        if sizes[key] > MAX_VALUES:
            raise ConfigError(
                f"config file '{where}': holds more than {MAX_VALUES:,} values once its YAML aliases "
                "(*name) are expanded; a study config holds a few thousand (an alias bomb?)"
            )
        stack.pop()
    return sizes[id(root)]


def read_config_text(text: str | bytes, where: str) -> dict:
    """The mapping a config file's ``text`` holds (``{}`` when empty); ``where`` names the
    file in every ConfigError: not YAML, too many values once aliases are expanded, an
    alias inside itself, a duplicate key, or a top level that is not a mapping."""
    loader = _StrictLoader(text)
    loader.name = where
    try:
        node = loader.get_single_node()
        if node is None:
            return {}
        _expanded_size(node, where)
        data = loader.construct_document(node)
    except yaml.YAMLError as err:
        raise ConfigError(f"config file '{where}' is not valid YAML: {err}") from err
    finally:
        loader.dispose()
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"config file '{where}': its top level is a {type(data).__name__}, not a mapping of "
            "keys (seed:, turbulence:, lucky:, base:, cases:, figures:)"
        )
    return data


def read_config_file(path) -> dict:
    """:func:`read_config_text` of the file ``path`` (a ConfigError when it cannot be read)."""
    try:
        text = Path(path).read_bytes()
    except FileNotFoundError as err:
        raise ConfigError(f"config file '{path}' not found") from err
    except OSError as err:
        raise ConfigError(f"config file '{path}' cannot be read ({err.strerror})") from err
    return read_config_text(text, str(path))
