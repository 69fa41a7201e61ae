"""Sphinx configuration of SceneFit's documentation (MyST Markdown).

Built by `make docs` and by tests/docs/test_docs_build.py with warnings as errors (-W) and nitpicky
(-n): a broken link, a missing page or a reference that no longer matches the code fails the build.
The CLI reference comes from the argparse parsers (sphinx-argparse), the jobs-file schema and the
presets table from the code (docs/_ext/).
"""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))


def _importable_package() -> None:
    """The repository root is the package `scenefit`; where it is not installed (a plain checkout),
    a temporary folder holding a link named scenefit makes it importable."""
    try:
        import scenefit  # noqa: F401
    except ImportError:
        holder = Path(tempfile.mkdtemp(prefix="scenefit-docs-"))
        (holder / "scenefit").symlink_to(ROOT, target_is_directory=True)
        sys.path.insert(0, str(holder))


_importable_package()

project = "SceneFit"
author = "SceneFit contributors"
extensions = ["myst_parser", "sphinxarg.ext", "dataclass_fields", "presets_table", "results_table"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_static/*.md"]
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
nitpicky = True
# Option names stay as typed: no "--" turned into a dash, no curly quotes in commands.
smartquotes = False
html_theme = "alabaster"
html_static_path = ["_static"]
html_theme_options = {"description": "Restyle a 3D asset to fit a photo", "fixed_sidebar": True}
html_show_sourcelink = False
# Pages link to the repository's own files (benchmarks, tests) as code spans, never over the network.
linkcheck_ignore = [r"https?://.*"]
