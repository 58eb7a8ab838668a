"""Sphinx configuration: the user pages (Markdown, through myst-parser) and the API reference
(docs/api.md: autodoc from the docstrings, NumPy style through napoleon).

    sphinx-build -W -b html docs docs/_build/html

``tests/test_sphinx.py`` builds it with warnings as errors, so a renamed argument or a broken
docstring fails the test suite, not the reader.
"""
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import spherevm  # noqa: E402

project = "spherevm"
author = "spherevm developers"
copyright = "spherevm developers"
version = release = spherevm.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "figures"]
# The pages link each other from index.md's table rather than a toctree; the table is checked by
# tests/test_docs.py::test_index_links_every_page.
suppress_warnings = ["toc.not_included"]

myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

autodoc_default_options = {"members": True, "member-order": "bysource", "show-inheritance": True}
autodoc_typehints = "description"
autodoc_typehints_description_target = "documented_params"
autosummary_generate = False
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False

html_theme = "alabaster"
html_title = f"spherevm {release}"
