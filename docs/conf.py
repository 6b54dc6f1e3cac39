"""Sphinx configuration of the cosim manual (``make docs`` -> docs/_build/html/index.html).

Everything comes from Debian 12 packages (python3-sphinx 5.3, python3-myst-parser 0.18,
furo), installed by ``make setup``. Pages are Markdown (MyST); the API reference
(api.md) is autodoc over the installed packages; the case-file reference
(reference/case-file.md) is generated from the pydantic schema by
``make docs-reference`` (cosim/schema_doc.py) and committed, never rebuilt here.
"""
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

project = "cosim"
author = "cosim contributors"
copyright = "cosim contributors, MIT licence"
with open(ROOT / "pyproject.toml", "rb") as _f:
    release = tomllib.load(_f)["project"]["version"]
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]

# MyST: $...$ / $$...$$ maths, ::: fences, and an anchor on every heading down to ###,
# so the existing links [x](#some-heading) and [x](page.md#heading) resolve.
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3

# autodoc: members in source order. The docstrings are plain reST prose (no numpy or
# Google sections), so no napoleon.
autodoc_member_order = "bysource"
# (no autodoc_default_options "members": in Sphinx 5.3 a default of True overrides the
# member lists that api.md gives some modules; each directive says :members: itself)

html_theme = "furo"
html_title = f"cosim {release}"
html_static_path = []
