"""Malformed inputs of every kind, refused on the command line: one line on stderr
naming the culprit, exit status 2, no traceback, nothing left behind.

The catalogue is tests/data/bad_inputs/cases.toml (its header says how a case
is written); the files the cases name live beside it, and the corrupt
recordings are made here from a short real one. Each case runs `hybrid.cli.main`
in a fresh working folder, with the simulation's stepping replaced by an
exception: a malformed input is refused before a single step, so an input that
is accepted fails at once instead of running. A case marked `pending` is one
the package does not refuse properly yet: a strict xfail, which fails the
moment the package handles it.
"""

from __future__ import annotations

import contextlib
import os
import resource
import struct
import subprocess
import sys
import tomllib
import zlib
from pathlib import Path

import pytest

from hybrid import cli
from hybrid.simulation import Simulation

HERE = Path(__file__).resolve().parent
DATA = HERE / "data" / "bad_inputs"
CATALOGUE = tomllib.loads((DATA / "cases.toml").read_text(encoding="utf-8"))
CASES = CATALOGUE["case"]
CATEGORIES = ("flags", "scene", "mesh", "mjcf", "recording")

# what every scratch folder ({tmp}) holds before a case: an ordinary file, and
# folders named like a scene file and a recording
SCRATCH = {"a_file.txt": "not a folder\n", "folder.toml/": None, "folder.mcap/": None}

#: the address space a case marked `memory_cap` may add (an input that asks for
#: too much memory then fails with MemoryError instead of exhausting the machine)
MEMORY_CAP_BYTES = 2 << 30

#: the recording the corrupt ones are made from (a membrane-only run of 10 frames)
RECORDED_S = 0.1


class Stepped(BaseException):
    """The simulation was stepped: the input was accepted and the run started.
    A BaseException, so that no handler of the command line catches it."""


# ------------------------------------------------------------------ generated inputs


def _records(blob: bytes):
    """(opcode, start, end) of each MCAP record: start at its opcode, end past its content."""
    pos, out = 8, []
    while pos + 9 <= len(blob):
        op, length = blob[pos], struct.unpack_from("<Q", blob, pos + 1)[0]
        out.append((op, pos, pos + 9 + length))
        if op == 0x02:  # the footer: the closing magic follows
            break
        pos += 9 + length
    return out


def _flip(blob: bytes, offset: int, bit: int = 0) -> bytes:
    b = bytearray(blob)
    b[offset] ^= 1 << bit
    return bytes(b)


def _png() -> bytes:
    """A valid 1x1 PNG."""

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", 1, 1, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\x00\xff\x00\x00"))
        + chunk(b"IEND", b"")
    )


def _nested_scene(depth: int) -> str:
    sel = '"all"'
    for _ in range(depth):
        sel = "{ union = [" + sel + "] }"
    return (
        f'[mesh]\ngenerator = "icosahedron"\n[masses]\ntotal_kg = 1.0\n[regions]\ndeep = {sel}\n'
        '[[constraints]]\ntype = "nailed"\nregion = "deep"\n'
    )


@pytest.fixture(scope="session")
def generated(tmp_path_factory) -> Path:
    """{gen}: inputs made rather than committed: corrupt copies of a short real
    recording, files of other kinds named .mcap, a scene nested 400 deep."""
    gen = tmp_path_factory.mktemp("bad_inputs_gen")
    rec = gen / "rec"
    status = cli.main(["run", str(DATA / "scenes" / "tiny.toml"), "--duration", str(RECORDED_S), "--out", str(rec)])
    assert status == 0
    good = (rec / "run.mcap").read_bytes()
    (gen / "good.mcap").write_bytes(good)
    records = _records(good)
    chunks = [(s, e) for op, s, e in records if op == 0x06]
    assert chunks, "the recording holds no chunk"
    s, e = chunks[0]
    # a chunk: opcode, length (8), start and end time (8 + 8), uncompressed size (8),
    # uncompressed CRC (4), compression name (4 + n), compressed size (8), the records
    crc_at = s + 9 + 24
    (gen / "chunk_bit.mcap").write_bytes(_flip(good, (s + e) // 2 + 4, 3))
    (gen / "chunk_crc_bit.mcap").write_bytes(_flip(good, crc_at, 0))
    (gen / "chunk_time_bit.mcap").write_bytes(_flip(good, s + 9 + 3, 6))
    (gen / "magic_bit.mcap").write_bytes(_flip(good, 1, 1))
    (gen / "footer_bit.mcap").write_bytes(_flip(good, len(good) - 8 - 4, 2))
    (gen / "truncated_header.mcap").write_bytes(good[:20])
    (gen / "magic_only.mcap").write_bytes(good[:8])
    (gen / "empty.mcap").write_bytes(b"")
    (gen / "picture.mcap").write_bytes(_png())
    (gen / "picture.png").write_bytes(_png())
    (gen / "text.mcap").write_text("a recording, honestly\n")
    (gen / "summary.mcap").write_bytes((rec / "summary.json").read_bytes())
    (gen / "deep_nesting.toml").write_text(_nested_scene(400))
    # a binary STL whose header claims 4e9 triangles (200 GB) in a file of one
    (gen / "huge_claim.stl").write_bytes(b"\0" * 80 + (4_000_000_000).to_bytes(4, "little") + b"\0" * 50)
    (gen / "huge_claim.toml").write_text('[mesh]\npath = "huge_claim.stl"\n[masses]\ntotal_kg = 1.0\n')
    return gen


# ------------------------------------------------------------------ one case


@contextlib.contextmanager
def _memory_cap(on: bool):
    if not on:
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as f:
        used = int(f.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (used + MEMORY_CAP_BYTES, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


def _expand(args, paths: dict) -> list[str]:
    return [a.format(**paths) for a in args]


def _contents(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")} if folder.exists() else set()


def _prepare(tmp_path: Path) -> dict:
    """A fresh working folder, scratch folder and (absent) output folder."""
    scratch = tmp_path / "scratch"
    for name, text in SCRATCH.items():
        p = scratch / name.rstrip("/")
        if text is None:
            p.mkdir(parents=True)
        else:
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text)
    (tmp_path / "cwd").mkdir()
    return {"tmp": scratch, "out": tmp_path / "out", "cwd": tmp_path / "cwd"}


def _check_left_behind(tmp_path: Path, where: dict, before: set[str]) -> None:
    out = where["out"]
    assert not out.exists() or (out.is_dir() and not any(out.iterdir())), (
        f"left behind in {{out}}: {sorted(_contents(out))}"
    )
    assert not _contents(where["cwd"]), f"left behind in the working folder: {sorted(_contents(where['cwd']))}"
    assert _contents(where["tmp"]) == before, f"changed in {{tmp}}: {sorted(_contents(where['tmp']) ^ before)}"
    extra = {p.name for p in tmp_path.iterdir()} - {"cwd", "scratch", "out"}
    assert not extra, f"written beside the working folder: {sorted(extra)}"


def _check_line(err: str, case: dict) -> None:
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1 and err.endswith("\n"), f"expected one line on stderr, received {lines!r}"
    for piece in case["culprit"]:
        assert piece in lines[0], f"{piece!r} not named in {lines[0]!r}"


def _params():
    for case in CASES:
        marks = [pytest.mark.xfail(strict=True, reason=case["pending"])] if "pending" in case else []
        yield pytest.param(case, id=case["id"], marks=marks)


@pytest.mark.parametrize("case", list(_params()))
def test_bad_input_is_refused_with_one_line(case, generated, tmp_path, monkeypatch, capsys):
    where = _prepare(tmp_path)
    before = _contents(where["tmp"])
    args = _expand(case["args"], {"data": DATA, "gen": generated, **where})
    for name, value in case.get("env", {}).items():
        monkeypatch.setenv(name, value)
    monkeypatch.chdir(where["cwd"])

    real_step, real_frames = Simulation.step, Simulation.step_frames

    def step(self, n=1):  # step(0) only loads the compiled step
        if n:
            raise Stepped(f"the input was accepted: the simulation stepped ({case['id']})")
        return real_step(self, 0)

    def step_frames(self, stops, frames):
        if len(stops):
            raise Stepped(f"the input was accepted: the simulation stepped ({case['id']})")
        return real_frames(self, stops, frames)

    monkeypatch.setattr(Simulation, "step", step)
    monkeypatch.setattr(Simulation, "step_frames", step_frames)
    capsys.readouterr()
    try:
        with _memory_cap(case.get("memory_cap", False)):
            status = cli.main(args)
    except SystemExit as exc:  # argparse's errors exit
        status = exc.code
    except Stepped as exc:
        pytest.fail(f"{exc}; stderr {capsys.readouterr().err!r}")
    err = capsys.readouterr().err
    assert status == 2, f"exit status {status}, stderr {err!r}"
    _check_line(err, case)
    _check_left_behind(tmp_path, where, before)


# ------------------------------------------------------------------ the catalogue itself


def test_catalogue_covers_every_kind_of_input():
    ids = [c["id"] for c in CASES]
    assert len(ids) == len(set(ids)), sorted({i for i in ids if ids.count(i) > 1})
    assert len(CASES) >= 110
    count = {k: sum(c["category"] == k for c in CASES) for k in CATEGORIES}
    assert all(c["category"] in CATEGORIES for c in CASES)
    assert min(count.values()) >= 8, count
    for c in CASES:
        assert isinstance(c["args"], list) and c["culprit"] and all(isinstance(p, str) and p for p in c["culprit"]), c[
            "id"
        ]


def test_every_input_file_is_used():
    """Each committed input file is named by a case, and each case's file exists."""
    named = " ".join(" ".join(c["args"]) for c in CASES)
    for p in sorted((DATA / "scenes").glob("*.toml")):
        assert f"{{data}}/scenes/{p.name}" in named, p.name
    referenced = " ".join(p.read_text(errors="replace") for p in (DATA / "scenes").glob("*.toml"))
    for folder in ("meshes", "mjcf"):
        for p in sorted((DATA / folder).iterdir()):
            assert p.name in referenced, p.name
    for c in CASES:
        for a in c["args"]:
            if a.startswith("{data}/") and "no_such" not in a:
                assert (DATA / a.removeprefix("{data}/")).exists(), (c["id"], a)


# ------------------------------------------------------------------ as a user runs it

SUBPROCESS = [c for c in CASES if c.get("subprocess") and "pending" not in c]


@pytest.mark.parametrize("case", SUBPROCESS, ids=[c["id"] for c in SUBPROCESS])
def test_bad_input_in_a_fresh_process(case, generated, tmp_path):
    where = _prepare(tmp_path)
    before = _contents(where["tmp"])
    args = _expand(case["args"], {"data": DATA, "gen": generated, **where})
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(HERE.parent), os.environ.get("PYTHONPATH", "")]),
        **case.get("env", {}),
    }
    proc = subprocess.run(
        [sys.executable, "-m", "hybrid", *args], capture_output=True, text=True, cwd=where["cwd"], env=env, timeout=120
    )
    assert proc.returncode == 2, proc
    _check_line(proc.stderr, case)
    _check_left_behind(tmp_path, where, before)
