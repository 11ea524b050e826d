"""The generated documentation pages: the scene-file reference, written from the
dataclasses; the validation, convergence and performance pages, written from the
studies' and the benchmark's JSON kept in docs/data/; the API reference, from
`hybrid.__all__`; the gallery of the scripts.

    python -m hybrid.docgen            # (re)write every generated page
    python -m hybrid.docgen --check    # exit status 1 if one is out of date
    python -m hybrid.docgen --rerun    # run the studies and the benchmark again (small
                                       # versions; --full for the full ones), store their
                                       # JSON and figures in docs/, then write the pages

Every term's keys, kinds, defaults and bounds come from its fields (`param(kind,
default, **meta)`) through the registry (`hybrid.terms.base.TERM_CLASSES`), the
top level's and `[mesh]`'s from `Scene` and `MeshSpec`: a new term or field
appears here without an edit. The tables whose fields carry no kind (masses,
selectors, schedules, the rigid part) are described below field by field, in
the order of their dataclasses' fields; a field added since gets a row from its
name (its unit), its default and its kind if it has one.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

# the `X as X` names: re-exported for tests/test_docs.py and tests/test_docs_site.py
from .gallery import render_gallery
from .paths import DATA as DATA
from .paths import DOC_PATH, DOCS, GALLERY_PATH, REFERENCE_PATH
from .reference import render_reference
from .rerun import rerun, rerun_gallery
from .scene_file import _MASSES as _MASSES
from .scene_file import _hand_rows as _hand_rows
from .scene_file import _valid as _valid
from .scene_file import render
from .study_pages import PAGES, STUDIES, render_study_page

__all__ = ["render", "render_pages", "render_study_page", "rerun", "DOC_PATH", "STUDIES", "PAGES", "main"]


def render_pages() -> dict[Path, str]:
    """{path: text} of every generated page."""
    pages = {DOC_PATH: render(), REFERENCE_PATH: render_reference(), GALLERY_PATH: render_gallery()}
    pages.update({DOCS / page: render_study_page(page) for page in PAGES})
    return pages


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m hybrid.docgen", description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path, default=None, help=f"write only the scene-file reference, here ({DOC_PATH})")
    p.add_argument("--check", action="store_true", help="only compare; exit status 1 if a page differs")
    p.add_argument("--rerun", nargs="*", metavar="STUDY", help=f"run these studies again first (all: {list(STUDIES)})")
    p.add_argument("--full", action="store_true", help="with --rerun: the full studies, not the small ones")
    p.add_argument("--gallery", nargs="*", metavar="SCRIPT", help="run these scripts again for the gallery (all)")
    p.add_argument("--quick", action="store_true", help="with --gallery: the scripts' --quick runs")
    args = p.parse_args(argv)
    if args.rerun is not None:
        unknown = sorted(set(args.rerun) - set(STUDIES))
        if unknown:
            sys.stderr.write(f"--rerun: no study {unknown}; expected some of {list(STUDIES)}\n")
            return 2
        rerun(args.rerun or None, full=args.full)
    if args.gallery is not None:
        rerun_gallery(args.gallery or None, quick=args.quick)
    pages = {args.out: render()} if args.out is not None else render_pages()
    if args.check:
        stale = [str(path) for path, text in pages.items() if not (path.is_file() and path.read_text("utf-8") == text)]
        for path in stale:
            sys.stderr.write(f"{path}: out of date; run python -m hybrid.docgen\n")
        return 1 if stale else 0
    for path, text in pages.items():
        if not path.parent.is_dir():
            sys.stderr.write(f"--out: no folder {str(path.parent)!r}; give --out a file in an existing folder\n")
            return 2
        path.write_text(text, encoding="utf-8")
        print(f"wrote {path}")
    return 0
