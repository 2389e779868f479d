"""The API reference, from the list of modules in ``docs/api_modules.py``.

``.. luckyao-api-reference::`` (in ``docs/api.rst``) becomes a section per subpackage and,
in each, autodoc's ``automodule`` of every listed module with its public members.
"""

from api_modules import API_MODULES
from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective
from sphinx.util.nodes import nested_parse_with_titles


def reference_rst() -> list[str]:
    lines = []
    for group in API_MODULES:
        modules = API_MODULES[group]
        if not modules:
            continue
        lines += [group, "-" * len(group), ""]
        for module in modules:
            lines += [f".. automodule:: {module}", "   :members:", ""]
    return lines


class ApiReference(SphinxDirective):
    """``.. luckyao-api-reference::``: every listed module, a section per subpackage."""

    has_content = False

    def run(self):
        container = nodes.container()
        nested_parse_with_titles(self.state, StringList(reference_rst(), source="docs/api_modules.py"), container)
        return container.children


def setup(app):
    app.add_directive("luckyao-api-reference", ApiReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
