"""Docstrings as autodoc reads them, made to mean what their authors wrote.

* Relative cross-references (``:mod:`.detector```, ``:class:`.cropped.CroppedFrames```) are
  written as Python's relative imports: a sibling of the docstring's module. Sphinx reads a
  leading dot as "any object whose name ends so", which is ambiguous where two subpackages
  have a module of that name (``wfs.detector`` and ``lucky.detector``). Each is made absolute,
  to the sibling, when that sibling exists.
* The command line's usage block (``luckyao.cli``'s module docstring, which is also its
  ``--help`` text, so written flush left, as the formatter keeps it) is shown literally.
"""

import importlib
import re

ROLE = re.compile(r":(mod|class|func|meth|attr|data|exc):`(~?)\.([A-Za-z_][\w.]*)`")
USAGE = "luckyao.cli"
"""The module whose docstring's lines after its first paragraph are a usage block."""


def _exists(path: str) -> bool:
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attribute in parts[cut:]:
                obj = getattr(obj, attribute)
        except AttributeError:
            return False
        return True
    return False


def _package_of(what: str, name: str) -> str:
    """The package a docstring's relative references start from: the module's own package
    (a package's docstring: the package itself)."""
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            module = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        if what == "module" and cut == len(parts) and hasattr(module, "__path__"):
            return module.__name__
        return module.__name__.rsplit(".", 1)[0]
    return name


def absolute_references(app, what, name, obj, options, lines):
    package = _package_of(what, name)

    def absolute(match):
        role, tilde, target = match.groups()
        candidate = f"{package}.{target}"
        if not _exists(candidate):
            return match.group(0)
        return f":{role}:`{target.rsplit('.', 1)[-1] if tilde else target} <{candidate}>`"

    lines[:] = [ROLE.sub(absolute, line) for line in lines]


def usage_block(app, what, name, obj, options, lines):
    if what == "module" and name == USAGE and "" in lines:
        blank = lines.index("")
        lines[:] = [*lines[:blank], "", "::", "", *("    " + line if line else "" for line in lines[blank + 1 :])]


def setup(app):
    app.connect("autodoc-process-docstring", usage_block, priority=100)  # before numpydoc
    app.connect("autodoc-process-docstring", absolute_references, priority=100)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
