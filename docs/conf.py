"""Sphinx configuration of the luckyao documentation: ``bash run.sh docs``.

Sphinx, as astropy, HCIPy and photutils: autodoc reads the package's docstrings (numpydoc
reads their sections where they have them; the rest is prose), sphinx-gallery runs the
examples of ``docs/examples/`` during the build, MyST lets the pages be Markdown, and small
local extensions (``docs/_ext/``) generate the configuration reference from the schema and
the API reference from ``docs/api_modules.py``, and mend docstrings as autodoc reads them.
"""

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
REPO = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS))

# the workflow's jobs compute on one thread; so do the gallery's examples (and their steps)
for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(variable, "1")
os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")
os.environ.setdefault("MPLBACKEND", "Agg")

import luckyao  # noqa: E402

project = "luckyao"
author = "the luckyao developers"
copyright = "the luckyao developers"
release = luckyao.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "numpydoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "config_reference",
    "api_reference",
    "docstring_fixes",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "examples/GALLERY_HEADER.rst", "**/*.ipynb", "sg_execution_times.rst"]
suppress_warnings = ["myst.header"]  # pages may open at a second-level heading after the title

myst_enable_extensions = ["dollarmath", "deflist", "colon_fence"]
myst_heading_anchors = 3

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_mock_imports = []
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "pydata_sphinx_theme"
html_title = "luckyao"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path = ["_static"]
html_css_files = ["luckyao.css"]
html_show_sourcelink = False
# pages without sub-pages: no (empty) left sidebar, the width for their tables
html_sidebars = {
    page: [] for page in ("index", "configuration", "results", "validation", "performance", "api", "changelog")
}


sphinx_gallery_conf = {
    "examples_dirs": ["examples"],
    "gallery_dirs": ["auto_examples"],
    "filename_pattern": r".*\.py$",  # run every example
    "within_subsection_order": "FileNameSortKey",
    "reset_argv": "gallery_hooks.reset_argv",  # docs/_ext/gallery_hooks.py
    "download_all_examples": False,
    "plot_gallery": "True",
    "abort_on_example_error": True,
    "remove_config_comments": True,
    "write_computation_times": False,
}
