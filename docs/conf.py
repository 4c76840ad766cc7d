"""Sphinx configuration of the AquaROM-FEniCSx manual (``make docs``; warnings are errors).

Pages generated from the code at every build (into ``_generated/``, not tracked): the scene
keys table from the scene schema, the ``--help`` of every command, and the validation report
when ``results/REPORT.md`` exists. The measured tables of the README and of the pages in
``measured.PAGES`` are rewritten in place from the snapshot ``data/`` (``generate.py``).
"""
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))
sys.path.insert(0, str(DOCS.parent))

project = "AquaROM-FEniCSx"
author = "the AquaROM-FEniCSx developers"
copyright = "the AquaROM-FEniCSx developers"

extensions = ["sphinx.ext.autodoc", "myst_parser"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "_generated/*.part.md", "data"]
html_theme = "alabaster"            # shipped with Sphinx: no theme from the network
html_static_path = []
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # signatures as written; the docstrings give units
myst_heading_anchors = 3
suppress_warnings = ["myst.header"]


def setup(app):
    from generate import write_generated_pages

    app.connect("builder-inited", lambda app: write_generated_pages(DOCS / "_generated"))
