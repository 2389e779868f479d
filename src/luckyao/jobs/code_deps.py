"""The source files a workflow step's results depend on: its module's import closure.

Snakemake reruns a job when an input file changes, but knows nothing of the
modules a command imports. Each rule therefore lists as inputs the files of
the import closure of the module its step runs (every ``luckyao`` module it
imports, at any depth and inside functions too, with the ``__init__.py`` of
every package on the way), computed from the source when the workflow is
parsed, so the list cannot drift from the code. The generated WFS kernels are
made from ``wfs/kernels.py`` and ``wfs/codelets.py``, which are in the closure
of every step that runs them.

The files are named relative to the study folder when it lies in the checkout
(``bash run.sh study``: the checkout itself), so a checkout moved or copied with
its finished study stays up to date; absolute otherwise (a study folder
elsewhere may move alone).
"""

import ast
import os
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
"""The ``luckyao`` package folder."""


def module_file(module: str, root: Path = PACKAGE_ROOT) -> Path:
    """The file of ``luckyao.a.b`` (a module or a package's ``__init__.py``)."""
    parts = module.split(".")[1:]
    path = root.joinpath(*parts)
    return path / "__init__.py" if path.is_dir() else path.with_suffix(".py")


def _imported_modules(path: Path, module: str) -> set[str]:
    """``luckyao`` modules imported anywhere in the file of ``module``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name.split(".")[0] == "luckyao"}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").split(".")[0] == "luckyao":
                target = node.module
            else:
                continue
            found.add(target)
            # ``from package import module`` imports the module too
            found |= {f"{target}.{alias.name}" for alias in node.names}
    return found


def _reexporting_module(name: str, root: Path) -> list[str]:
    """The module that re-exports object ``luckyao.pkg.Name`` from package ``luckyao.pkg``'s
    ``EXPORTS`` (:mod:`luckyao.exports`), as a list (empty if none)."""
    package, _, obj = name.rpartition(".")
    init = module_file(package, root)
    if init.name != "__init__.py" or not init.exists():
        return []
    for node in ast.parse(init.read_text(), filename=str(init)).body:
        if isinstance(node, ast.Assign) and [getattr(t, "id", None) for t in node.targets] == ["EXPORTS"]:
            return [f"{package}.{module}" for module, names in ast.literal_eval(node.value).items() if obj in names]
    return []


def import_closure(module: str, root: Path = PACKAGE_ROOT) -> list[Path]:
    """Sorted files of ``module`` and everything it imports from ``luckyao``,
    including the ``__init__.py`` of each package they live in."""
    seen, files, todo = set(), set(), [module]
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        path = module_file(name, root)
        if not path.exists():  # an object imported from a package, not a module: the module it re-exports
            todo += _reexporting_module(name, root)
            continue
        files.add(path)
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]  # parent packages run first
        todo += sorted(_imported_modules(path, name))
    return sorted(files)


def step_sources(module: str, root: Path = PACKAGE_ROOT, workdir=None) -> list[str]:
    """Files a workflow step's results depend on: the import closure of its module
    (``luckyao.steps.simulation``) plus the command line that dispatches to it
    (``python -m luckyao``; its per-step imports are lazy, so only its own files);
    relative to ``workdir`` (default: here, the study folder) when it lies in the
    checkout (``root``'s ``src/..``)."""
    entry = [module_file(m, root) for m in ("luckyao.__main__", "luckyao.cli")]
    files = sorted(set(import_closure(module, root)) | set(entry))
    workdir = Path(workdir or os.getcwd()).resolve()
    if workdir.is_relative_to(root.resolve().parents[1]):
        return [os.path.relpath(p, workdir) for p in files]
    return [str(p) for p in files]
