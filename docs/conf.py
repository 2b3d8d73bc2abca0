"""Sphinx configuration of the triaxcal documentation (``make docs``).

Everything that other parts of the project can change is generated at build time: the API
reference from ``triaxcal.__all__`` (grouped by the pipeline stage whose ``__all__`` lists each
name), the command-line reference from ``triaxcal.cli.build_parser()``, and the gallery, whose
examples run during the build (``docs/_ext/triaxcal_docs.py``, sphinx-gallery). The pages load
nothing from the network: the theme's assets are bundled, no math renderer is used, and the
cross-links to numpy, scipy and Python come from small inventories kept in ``docs/_inventories``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE))  # gallery_data: where the gallery reads real recordings

os.environ.setdefault("MPLBACKEND", "Agg")

import triaxcal  # noqa: E402

project = "triaxcal"
author = "triaxcal developers"
copyright = "the triaxcal developers"
release = triaxcal.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.intersphinx",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "triaxcal_docs",  # API stage pages, CLI reference, offline checks
]

smartquotes = False  # "--radius" stays two hyphens, as the command line spells it
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "sg_execution_times.rst", "benchmarks/results.md",
                    "**/GALLERY_HEADER.rst", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]
suppress_warnings = ["config.cache"]  # sphinx-gallery's callables in the config

# -- Markdown (MyST) --------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# -- API: autodoc, autosummary, numpydoc ------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"  # numpydoc's Parameters sections say the types
add_module_names = False
numpydoc_show_class_members = False  # members come from the autosummary class template
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = True
numpydoc_xref_ignore = "all"  # link only the names below; the rest stay plain words
numpydoc_xref_aliases = {
    "ndarray": "numpy.ndarray",
    "array": "numpy.ndarray",
    "array_like": ":term:`numpy:array_like`",
    "array-like": ":term:`numpy:array_like`",
    "Generator": "numpy.random.Generator",
    "Path": "pathlib.Path",
    "path-like": ":term:`python:path-like object`",
    "PathLike": "os.PathLike",
    "Sequence": "collections.abc.Sequence",
    "Mapping": "collections.abc.Mapping",
    "Iterable": "collections.abc.Iterable",
    "Iterator": "collections.abc.Iterator",
    "Callable": "collections.abc.Callable",
    "CalibrationError": "triaxcal.CalibrationError",
    "SensorCalibration": "triaxcal.SensorCalibration",
    "Calibration": "triaxcal.Calibration",
    "EllipsoidFit": "triaxcal.EllipsoidFit",
}

# -- cross-links: offline inventories (see docs/_inventories/make_inventories.py) -------------
intersphinx_mapping = {
    "python": ("https://docs.python.org/3/", str(HERE / "_inventories" / "python.inv")),
    "numpy": ("https://numpy.org/doc/stable/", str(HERE / "_inventories" / "numpy.inv")),
    "scipy": ("https://docs.scipy.org/doc/scipy/", str(HERE / "_inventories" / "scipy.inv")),
}

# -- gallery ----------------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",  # every example runs during the build
    "ignore_pattern": r"__init__\.py|gallery_data\.py",
    "within_subsection_order": "triaxcal_docs.GalleryOrder",  # the pipeline's order
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "doc_module": ("triaxcal",),
    "backreferences_dir": "reference/api/backrefs",  # the examples that use each name
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "show_memory": False,
    "min_reported_time": 1,
    "plot_gallery": "True",
    "write_computation_times": False,  # its page loads DataTables from a CDN
}

# -- HTML -------------------------------------------------------------------------------------
html_theme = "furo"  # its CSS and JS are in the wheel: nothing from a CDN
html_title = f"triaxcal {release}"
html_static_path = ["_static"]
html_css_files = ["triaxcal.css"]
html_show_sourcelink = False
html_copy_source = False
html_theme_options = {
    "source_repository": "",
    "navigation_with_keys": True,
}
