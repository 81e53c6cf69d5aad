"""Sphinx configuration of kinecal's documentation site (``make docs``).

The pages are the Markdown files of docs/ (MyST), the README and the examples' notes; the
API reference (docs/api/, written by docs/api_pages.py) is generated from the numpydoc
docstrings of the public packages. ``make docs`` builds with warnings as errors.
"""

from __future__ import annotations

from kinecal._version import __version__

project = "kinecal"
author = "kinecal developers"
copyright = "2026, the kinecal developers"
version = release = __version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "api_pages.py", "conf.py"]

# MyST: GitHub-style heading anchors (the pages link to #sections), $ math, tables.
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath", "colon_fence"]

# Autodoc: the documented names are those listed on the API pages (every __all__).
autodoc_typehints = "none"
autodoc_member_order = "bysource"
autodoc_default_options = {"members": False}
autosummary_generate = False

# numpydoc: the class pages list their methods through autodoc (no member tables).
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

html_theme = "alabaster"
html_title = f"kinecal {__version__}"
html_static_path: list[str] = []


# Autosummary's one-line summaries end at the first full stop; the docstrings cite the
# paper as "Eq. 21", "Sec. 4", "Fig. 6", which are not sentence ends.
try:
    import sphinx.ext.autosummary as _autosummary

    _autosummary.WELL_KNOWN_ABBREVIATIONS = (
        *_autosummary.WELL_KNOWN_ABBREVIATIONS,
        *("Eq.", "Eqs.", "Sec.", "Fig.", "Figs.", "cf."),
    )
except (ImportError, AttributeError):  # another Sphinx: summaries cut at those stops
    pass


def _constant_docstring(app, what, name, obj, options, lines):
    """A public constant (an int, a tuple, a dict) has no docstring of its own: show its
    value where it is short, not the docstring of its type."""
    import inspect

    if inspect.isclass(obj) or inspect.isroutine(obj) or inspect.ismodule(obj):
        return
    own = " ".join((inspect.getdoc(type(obj)) or "").split())
    if " ".join(" ".join(lines).split()) not in ("", own):
        return
    lines.clear()
    value = repr(obj)
    if len(value) <= 100:
        lines.append(f"Constant: ``{value}``.")
    else:
        lines.append(f"Constant ({type(obj).__name__} of {len(obj)} entries).")


def setup(app):
    # Before numpydoc (priority 500), which rewrites the docstring.
    app.connect("autodoc-process-docstring", _constant_docstring, priority=100)
