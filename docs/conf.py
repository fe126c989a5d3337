"""Sphinx configuration: the API reference from numpydoc docstrings, pages in Markdown (MyST).

Build with ``make docs`` (or ``python -m sphinx -b html docs docs/_build/html``); the
``docs`` extra installs Sphinx, numpydoc and myst-parser. The Python snippets of the
Markdown pages are executed by ``tests/test_docs_snippets.py``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

project = "manip_id"
author = "manip_id developers"
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]
myst_enable_extensions = ["dollarmath"]
autodoc_typehints = "none"  # numpydoc shows the documented types and shapes
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_validation_checks: set[str] = set()
html_theme = "alabaster"
