"""The reference documentation (docs/): the scene-file reference is the one the
dataclasses generate, its ranges are the checks', every public name, trace and
summary key and recording channel is documented, and every file a document or a
docstring refers to exists."""

from __future__ import annotations

import dataclasses
import re
import subprocess
from pathlib import Path

import pytest

import hybrid
from hybrid import docgen
from hybrid.errors import SceneError
from hybrid.terms import base
from hybrid.terms.base import Term, check_value, force, param

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted((REPO / "docs").glob("*.md"))
# files a document asks the reader to create (the architecture page's example term)
TO_CREATE = {"hybrid/terms/floor.py"}


def test_the_scene_file_reference_is_the_one_the_dataclasses_generate():
    assert docgen.DOC_PATH.read_text(encoding="utf-8") == docgen.render(), (
        "docs/scene-file.md is out of date with the dataclasses: run `python -m hybrid.docgen`"
    )


def _sections(text: str) -> dict:
    """{'type = "muscle"': section text} for each term's section."""
    parts = re.split(r"^### `(type = \"\w+\")`", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_every_term_and_every_field_has_its_row():
    sections = _sections(docgen.render())
    assert len(base.TERM_CLASSES) >= 12
    for cls in base.TERM_CLASSES:
        section = sections[f'type = "{cls.toml_type}"']
        for f in dataclasses.fields(cls):
            assert f"| `{f.name}` |" in section, (cls.__name__, f.name)


def _bounded_fields():
    """(where, field) of every field with a kind: the scene's, the mesh's, the terms'."""
    from hybrid.scene import MeshSpec, Scene

    for cls in (Scene, MeshSpec, *base.TERM_CLASSES):
        for f in dataclasses.fields(cls):
            if f.metadata.get("kind") in ("positive", "nonneg", "angle_deg", "integer"):
                yield f"{cls.__name__}.{f.name}", f


def _refused(kind, value, meta) -> bool:
    try:
        check_value("x", kind, value, meta)
    except SceneError:
        return True
    return False


def test_the_documented_ranges_are_what_the_checks_refuse():
    fields = list(_bounded_fields())
    assert len(fields) > 10
    for where, f in fields:
        kind, meta = f.metadata["kind"], f.metadata
        text = docgen._valid(kind, meta)
        integer = kind == "integer"
        step = 1 if integer else 1e-9
        m = re.fullmatch(r"an? (?:number|integer) (>=?) (\S+?)(?: and <= (\S+))?", text)
        if m:
            lo = int(m[2]) if integer else float(m[2])
            assert _refused(kind, lo, meta) == (m[1] == ">"), where
            assert _refused(kind, lo - step, meta), where
            assert not _refused(kind, lo + step, meta), where
            if m[3]:
                hi = float(m[3])
                assert not _refused(kind, hi, meta) and _refused(kind, hi * (1 + 1e-9), meta), where
            continue
        m = re.fullmatch(r"an integer in (\d+)\.\.(\d+)", text) or re.fullmatch(r"a number in \((\S+), (\S+)\)", text)
        assert m, (where, text)
        lo, hi = (int(m[1]), int(m[2])) if integer else (float(m[1]), float(m[2]))
        closed = integer  # "lo..hi" includes its ends, "(lo, hi)" excludes them
        assert _refused(kind, lo, meta) != closed and _refused(kind, hi, meta) != closed, where
        assert _refused(kind, lo - step, meta) and _refused(kind, hi + step, meta), where
        assert not _refused(kind, (lo + hi) // 2 if integer else 0.5 * (lo + hi), meta), where


def test_a_new_term_appears_without_an_edit_of_the_generator(monkeypatch):
    @force("floor_for_docs")
    class FloorForDocs(Term):
        """A soft floor pushing points back up."""

        stiffness_n_per_m: float = param("positive", hi=1e6)
        point_m: tuple = param("vec3", (0.0, 0.0, 0.0))

    monkeypatch.setitem(base.FORCE_TYPES, "floor_for_docs", FloorForDocs)
    section = _sections(docgen.render())['type = "floor_for_docs"']
    assert "A soft floor pushing points back up." in section
    assert "| `stiffness_n_per_m` | N/m | *required* | a number > 0 and <= 1e6 |" in section
    assert "| `point_m` | m | [0.0, 0.0, 0.0] | [x, y, z], finite |" in section
    # a kind of value added since is described by the bounds its field declares
    assert docgen._valid("young_modulus", {"lo": 0, "hi": 1e9}) == "a young modulus value >= 0 and <= 1e9"


def test_a_field_added_to_a_table_without_kinds_gets_a_row():
    from hybrid.scene import Masses

    @dataclasses.dataclass(frozen=True)
    class MoreMasses(Masses):
        lumped_kg: float = 0.5
        spread: str = param("choice", "area", choices=("area", "volume"))

    rows = docgen._hand_rows(MoreMasses, docgen._MASSES)
    assert "| `lumped_kg` | kg | 0.5 | see MoreMasses |" in rows
    assert '| `spread` | - | "area" | one of "area", "volume" |' in rows
    assert sum(r.startswith("| `total_kg` | kg |") for r in rows) == 1


def test_the_check_command_says_when_the_file_is_stale(tmp_path, capsys):
    path = tmp_path / "scene-file.md"
    assert docgen.main(["--out", str(path)]) == 0
    assert docgen.main(["--check", "--out", str(path)]) == 0
    path.write_text(path.read_text() + "edited by hand\n")
    assert docgen.main(["--check", "--out", str(path)]) == 1
    assert "out of date" in capsys.readouterr().err


# ---------------------------------------------------------------- what the documents name


def _tracked_top_level() -> set:
    try:
        files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout
        return {line.split("/")[0] for line in files.splitlines() if line}
    except (OSError, subprocess.CalledProcessError):
        return {p.name for p in REPO.iterdir()}


def _references(path: Path, top: set) -> list[str]:
    """The repository files a markdown file refers to: link targets, paths whose first
    part is a top-level entry of the repository, and bare NAME.md; fenced code left out."""
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.M | re.S)
    refs = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if not re.match(r"[a-z]+:|#", target):
            refs.append(target.split("#")[0])
    for token in re.findall(r"(?<![\w/.~-])([\w.-]+(?:/[\w.*<>-]+)+/?)", text):
        if token.split("/")[0] in top and not re.search(r"[*<>]", token):
            refs.append(token)
    refs += re.findall(r"(?<![\w/.-])([\w-]+\.md)\b", text)
    return refs


@pytest.mark.parametrize("doc", [REPO / "README.md", *DOCS], ids=lambda p: p.name)
def test_every_file_a_document_names_exists(doc):
    top = _tracked_top_level()
    refs = _references(doc, top)
    assert refs, "no reference found: the parser is broken"
    missing = [r for r in refs if r not in TO_CREATE and not ((doc.parent / r).exists() or (REPO / r).exists())]
    assert not missing, f"{doc.name} names files not in the repository: {missing}"


def test_no_docstring_names_a_document_outside_the_repository():
    missing = []
    for path in sorted((REPO / "hybrid").rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        for name in set(re.findall(r"\b(?:docs/)?[A-Z][A-Z_]+\.md\b|\bdocs/[\w-]+\.md\b", text)):
            if not (REPO / name).exists() and not (REPO / "docs" / name).exists():
                missing.append(f"{path.relative_to(REPO)}: {name}")
    assert not missing, missing


def test_the_references_are_read_at_all():
    """The parser finds what it must: a missing file is reported."""
    fake = REPO / "docs" / "architecture.md"
    refs = _references(fake, _tracked_top_level())
    assert "tests/test_layers.py" in refs and "hybrid/terms/floor.py" in refs


# ---------------------------------------------------------------- names, keys, channels


def test_the_api_page_names_every_public_name():
    text = (REPO / "docs" / "api.md").read_text(encoding="utf-8")
    missing = [name for name in hybrid.__all__ if f"`{name}" not in text and f"hybrid.{name}" not in text]
    assert not missing, f"docs/api.md does not document {missing}"


def test_the_metrics_page_defines_every_trace_and_summary_key():
    from hybrid.run import TRACE_KEYS

    text = (REPO / "docs" / "metrics.md").read_text(encoding="utf-8")
    result = hybrid.run(hybrid.load("membrane_demo"), 0.05)
    keys = set(TRACE_KEYS) | set(result["summary"])
    assert set(result["trace"].arrays()) == set(TRACE_KEYS)
    missing = sorted(k for k in keys if f"`{k}`" not in text)
    assert not missing, f"docs/metrics.md does not define {missing}"


def test_the_recording_page_lists_every_channel():
    from hybrid.record import TOPICS

    text = (REPO / "docs" / "recording.md").read_text(encoding="utf-8")
    missing = [t for t in TOPICS if f"`{t}`" not in text and f'"{t}"' not in text]
    assert not missing, f"docs/recording.md does not list {missing}"


def test_the_reference_example_is_a_valid_scene():
    import tomllib

    from hybrid.model import compile_scene
    from hybrid.scenefile import scene_from_dict

    example = re.search(r"```toml\n(.*?)```", docgen.render(), re.S)[1]
    scene = scene_from_dict(tomllib.loads(example), source="docs/scene-file.md")
    assert compile_scene(scene).nvert == 162 and scene.formulation == "continuum"
