"""Re-exports of a subpackage's public objects, imported on first use (PEP 562).

Each subpackage's ``__init__.py`` names its public objects by module (``EXPORTS``) and
re-exports them from here: ``from luckyao.lucky import run_lucky`` works, yet importing a
package imports none of its modules. So a module's import closure (which is a workflow
step's code inputs, :mod:`luckyao.jobs.code_deps`) holds only the modules it names, and
``code_deps`` follows a name imported from a package to the module ``EXPORTS`` gives.
"""

from importlib import import_module


def lazy_exports(package: str, exports: dict[str, tuple[str, ...]]):
    """``__all__``, ``__getattr__`` and ``__dir__`` of ``package`` for ``exports`` (module -> names)."""
    module_of = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str):
        if name in module_of:
            return getattr(import_module(f"{package}.{module_of[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(module_of)

    return sorted(module_of), __getattr__, __dir__
