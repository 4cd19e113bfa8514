"""Sphinx configuration of posturegen's documentation (MyST Markdown, autodoc).

Build: sphinx-build -W -b html docs docs/_build (CI builds it with warnings as errors)."""

from __future__ import annotations

project = "posturegen"
author = "posturegen developers"
copyright = "2026, posturegen developers"  # noqa: A001 - Sphinx's name
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon"]
source_suffix = {".md": "markdown"}
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
exclude_patterns = ["_build"]
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the signatures show them; the docstrings state units
html_theme = "alabaster"
suppress_warnings = ["myst.xref_missing"]  # README-style links to sections by name
