"""The documentation site (docs/, mkdocs.yml) and the first page: the generated pages
match what they are generated from (the studies' JSON, hybrid.__all__, scripts/),
every link resolves, the README stays a first page."""

from __future__ import annotations

import copy
import json
import re
import shutil
from pathlib import Path

import pytest

import hybrid
from hybrid import docgen

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"


@pytest.mark.parametrize("page", ["reference.md", "gallery.md", *docgen.PAGES])
def test_each_generated_page_is_the_one_its_sources_make(page):
    path = DOCS / page
    assert path.read_text(encoding="utf-8") == docgen.render_pages()[path], (
        f"docs/{page} is out of date: run `python -m hybrid.docgen`"
    )


def _numbers_changed(obj):
    """obj with every number changed, keeping its type (a count stays a whole number)."""
    if isinstance(obj, dict):
        return {k: _numbers_changed(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_numbers_changed(v) for v in obj]
    if isinstance(obj, int) and not isinstance(obj, bool):
        return 2 * obj + 1
    if isinstance(obj, float):
        return 1.37 * obj + 0.11
    return obj


@pytest.mark.parametrize("page", list(docgen.PAGES))
def test_a_json_edited_without_regenerating_fails(page, tmp_path):
    """Each study's numbers, and who made them, reach the page: a JSON edited and not
    regenerated leaves a page that the test above refuses."""
    _, _, names = docgen.PAGES[page]
    shown = (DOCS / page).read_text(encoding="utf-8")
    for name in names:
        study = docgen.STUDIES[name]
        data = tmp_path / name
        shutil.copytree(docgen.DATA, data)
        stored = json.loads((data / study.json_name).read_text(encoding="utf-8"))
        assert set(stored["made_by"]) >= {"command", "date_utc", "version", "machine"}
        for edit in ("result", "made_by"):
            edited = copy.deepcopy(stored)
            if edit == "result":
                edited["result"] = _numbers_changed(stored["result"])
            else:
                edited["made_by"]["command"] += " --changed"
            (data / study.json_name).write_text(json.dumps(edited), encoding="utf-8")
            assert docgen.render_study_page(page, data=data) != shown, (page, name, edit)


def test_every_page_traces_each_study_to_its_json_and_command():
    for page, (_, _, names) in docgen.PAGES.items():
        text = (DOCS / page).read_text(encoding="utf-8")
        for name in names:
            study = docgen.STUDIES[name]
            made = json.loads((docgen.DATA / study.json_name).read_text(encoding="utf-8"))["made_by"]
            assert f"(data/{study.json_name})" in text and f"`{made['command']}`" in text, (page, name)


def test_the_api_reference_lists_every_public_name():
    text = (DOCS / "reference.md").read_text(encoding="utf-8")
    entries = re.findall(r"^## `hybrid\.(\w+)`\n\n::: ([\w.]+)$", text, flags=re.M)
    assert [name for name, _ in entries] == list(hybrid.__all__)
    for name, where in entries:  # each entry names where the object is defined
        module, _, qualname = where.rpartition(".")
        assert getattr(__import__(module, fromlist=["_"]), qualname) is getattr(hybrid, name), name


def test_the_gallery_shows_every_scripts_figure():
    import matplotlib.image as mpimg

    text = (DOCS / "gallery.md").read_text(encoding="utf-8")
    scripts = sorted(p.stem for p in (REPO / "scripts").glob("*.py") if not p.name.startswith("_"))
    assert len(scripts) >= 8
    for name in scripts:
        assert f"## `scripts/{name}.py`" in text and f"](figures/gallery/{name}.png)" in text, name
        img = mpimg.imread(DOCS / "figures" / "gallery" / f"{name}.png")[..., :3]
        assert (img.min(axis=2) < 0.5).mean() > 0.005, name  # lines drawn, not a blank page


def _slug(heading: str) -> str:
    """A heading's anchor as Python-Markdown's toc makes it (mkdocs' default)."""
    text = re.sub(r"[`*_]|<[^>]+>", "", heading).strip().lower()
    text = re.sub(r"[^\w\s-]", "", text)
    return re.sub(r"[-\s]+", "-", text).strip("-")


def _anchors(path: Path) -> set:
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    return {_slug(h) for h in re.findall(r"^#+ (.+)$", text, flags=re.M)}


def _links(path: Path) -> list[str]:
    """The targets of the markdown links and images of a page, outside code."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    text = re.sub(r"`[^`\n]*`", "", text)
    return re.findall(r"!?\[[^\]]*\]\(([^)\s]+)\)", text)


PAGES = [REPO / "README.md", REPO / "CHANGELOG.md", *sorted(DOCS.glob("*.md"))]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_link_resolves(page):
    links = _links(page)
    broken = []
    for target in links:
        if re.match(r"[a-z]+:", target):  # no page links outside the repository: it is read offline too
            broken.append(f"{target} (an address outside the repository)")
            continue
        file, _, anchor = target.partition("#")
        where = (page.parent / file).resolve() if file else page
        if not where.is_file():
            broken.append(target)
        elif anchor and where.suffix == ".md" and anchor not in _anchors(where):
            broken.append(f"{target} (no such heading)")
    assert not broken, f"{page.name}: {broken}"


def test_the_link_checker_sees_a_broken_link(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("# Top\n\n[a](missing.md) [b](#top) [c](#nowhere) `[d](x.md)`\n", encoding="utf-8")
    assert _links(page) == ["missing.md", "#top", "#nowhere"]
    assert "top" in _anchors(page) and "nowhere" not in _anchors(page)


def test_the_readme_is_a_first_page():
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    # the two set-up commands, the second exactly what .ci/run runs
    assert 'pip install -e ".[test]" && hybrid run\npython -m pytest -q\n' in text
    assert "\npython -m pytest -q\n" in (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert "FINDINGS" not in text  # a document the repository does not hold


def test_every_page_is_in_the_sites_navigation():
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    missing = [p.name for p in DOCS.glob("*.md") if f": {p.name}\n" not in nav]
    assert not missing, missing


def test_the_citation_names_this_package_and_the_paper():
    import tomllib

    import yaml

    cff = yaml.safe_load((REPO / "CITATION.cff").read_text(encoding="utf-8"))
    name = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["name"]
    assert cff["title"].startswith(name) and cff["license"] == "MIT" and "version" not in cff  # the version: one place
    (paper,) = cff["references"]
    assert [a["family-names"] for a in paper["authors"]] == ["Promayon", "Baconnier", "Puech"]
    assert paper["year"] == 1997
