"""Sphinx configuration of the vfinfer documentation site (``make docs``).

The command-line page and the REST page are generated here, at build time, from the typer app and from
``create_app().openapi()``, so they cannot drift from the code.
"""

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import _generate  # noqa: E402  (needs the path above)

project = "vfinfer"
author = "the vfinfer authors"
release = "0.1.0"

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "_generated/*.md"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# numpydoc-style docstrings; the signature carries the types, the description their units
napoleon_google_docstring = False
napoleon_numpy_docstring = True
autodoc_member_order = "bysource"
autodoc_typehints = "none"
autodoc_default_options = {"members": False, "show-inheritance": False}

# A `{ref}`/`:ref:` to a missing label, a link to a missing page and an unreadable image always warn, so
# `make docs` (-W) fails on them. Nitpicky mode would also demand that every Python name a docstring mentions
# resolve, which a reference page of the library's face (not every module) cannot give.
nitpicky = False

html_theme = "alabaster"
html_title = "vfinfer"
html_static_path = []
html_theme_options = {"description": "Vocal-fold properties from a glottal area waveform", "page_width": "1100px"}


def setup(app):
    app.connect("builder-inited", lambda app: _generate.write_all(HERE / "_generated"))
