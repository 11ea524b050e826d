"""Where the generated pages and what they are made from live in the repository."""

from __future__ import annotations

from pathlib import Path

#: the documentation folder
DOCS = Path(__file__).resolve().parents[2] / "docs"
#: the scene-file reference
DOC_PATH = DOCS / "scene-file.md"
#: where the studies' JSON is kept
DATA = DOCS / "data"
REFERENCE_PATH = DOCS / "reference.md"
GALLERY_PATH = DOCS / "gallery.md"
SCRIPTS = DOCS.parent / "scripts"
#: where the gallery's figures are, one per script: figures/gallery/NAME.png
GALLERY_FIGURES = DOCS / "figures" / "gallery"
