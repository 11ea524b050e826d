"""The package's layers (docs/architecture.md): every import points down or
sideways within a layer, no import closes a circle, and only the rigid and
coupling modules name MuJoCo. The imports are read from the sources (AST),
function-level imports included, so a lazy import cannot hide a circle.
"""

from __future__ import annotations

import ast
import fnmatch
import textwrap
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "hybrid"

# Bottom to top. A module imports only modules of its own layer or below.
LAYERS = (
    ("errors, kernel", ("errors", "kernel", "calls", "checks", "integrators")),
    ("geometry, regions, schedules", ("mesh", "mesh.*", "regions", "schedule", "stability", "sites")),
    ("terms", ("terms", "terms.*")),
    ("scene", ("scene", "scenefile", "scenefile.*", "rigidfile", "demo", "resolve")),
    ("model, rigid", ("model", "body", "rigid", "rigid.*")),
    (
        "step",
        (
            "step",
            "step_work",
            "switches",
            "readouts",
            "implicit",
            "implicit_work",
            "implicit_matrix",
            "implicit_lungs",
            "wall_coupling",
        ),
    ),
    ("step loop", ("loop", "loop_compile")),
    ("coupled step", ("coupling",)),
    ("simulation", ("simulation", "solvers", "builds", "control", "state", "diagnosis", "anatomy", "anatomy.*")),
    (
        "observers",
        (
            "run",
            "observers",
            "observers.*",
            "loads",
            "record",
            "record.*",
            "render",
            "pictures",
            "pictures.*",
            "sweep",
            "grid",
            "outputs",
            "provenance",
            "respiratory",
        ),
    ),
    ("public API", ("",)),  # hybrid/__init__.py
    (
        "bench, command line, studies",
        (
            "bench",
            "bench.*",
            "bench_rigid",
            "cli",
            "compile_estimate",
            "__main__",
            "docgen",
            "docgen.*",
            "inspection",
            "studies",
            "studies.*",
        ),
    ),
)
# the door to MuJoCo: model time (rigid) and step time (coupling)
MUJOCO_DOOR = ("rigid", "rigid.*", "coupling")


def module_name(path: Path, root: Path) -> str:
    """'' for the package itself, 'terms.base' for hybrid/terms/base.py."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(name: str) -> int:
    for k, (_, patterns) in enumerate(LAYERS):
        if any(fnmatch.fnmatchcase(name, p) for p in patterns):
            return k
    raise KeyError(name)


def imports_of(path: Path, root: Path, modules: set) -> tuple[set, set]:
    """(package modules imported, top-level names of other imports) by the module at path."""
    me = module_name(path, root)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    ours, others = set(), set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "hybrid" or a.name.startswith("hybrid."):
                    ours.add(a.name[len("hybrid.") :] if a.name != "hybrid" else "")
                else:
                    others.add(a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".") if package else []
                base = base[: len(base) - (node.level - 1)]
                target = ".".join([*base, *(node.module.split(".") if node.module else [])])
            elif node.module == "hybrid" or (node.module or "").startswith("hybrid."):
                target = node.module[len("hybrid.") :] if node.module != "hybrid" else ""
            else:
                others.add((node.module or "").split(".")[0])
                continue
            # `from . import x` and `from .pkg import mod` name modules themselves
            subs = {f"{target}.{a.name}".lstrip(".") for a in node.names} & modules
            ours |= subs or {target}
    ours.discard(me)
    return ours, others


def package_graph(root: Path) -> tuple[dict, dict]:
    paths = {module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    graph, external = {}, {}
    for name, path in paths.items():
        graph[name], external[name] = imports_of(path, root, set(paths))
    return graph, external


def violations(root: Path) -> list[str]:
    """Every upward import, unlayered module, circle and MuJoCo import outside the door."""
    graph, external = package_graph(root)
    out = []
    for name, deps in graph.items():
        try:
            mine = layer_of(name)
        except KeyError:
            out.append(f"hybrid.{name}: in no layer of tests/test_layers.py (add it where it belongs)")
            continue
        for dep in sorted(deps):
            if dep not in graph:
                out.append(f"hybrid.{name} imports hybrid.{dep}, which does not exist")
            elif layer_of(dep) > mine:
                out.append(
                    f"hybrid.{name} ({LAYERS[mine][0]}) imports hybrid.{dep or '(package)'} "
                    f"({LAYERS[layer_of(dep)][0]}): an upward import"
                )
        if "mujoco" in external[name] and not any(fnmatch.fnmatchcase(name, p) for p in MUJOCO_DOOR):
            out.append(f"hybrid.{name or '(package)'} imports mujoco outside hybrid.rigid and hybrid.coupling")
    out += [f"import circle: {' -> '.join('hybrid.' + m for m in c)}" for c in _circles(graph)]
    return out


def _circles(graph: dict) -> list[list[str]]:
    """One circle per strongly connected component of more than one module (Tarjan)."""
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in graph:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp) + [sorted(comp)[0]])

    for v in graph:
        if v not in index:
            visit(v)
    return comps


def test_the_package_imports_only_point_down_with_no_circle_and_mujoco_behind_its_door():
    assert violations(PACKAGE) == []


def test_no_library_module_imports_the_command_line():
    graph, _ = package_graph(PACKAGE)
    front = {"cli", "__main__", "studies.cli"}
    users = sorted(n for n, deps in graph.items() if deps & {"cli"} and n not in front)
    assert users == []


def _fake_package(tmp_path: Path, files: dict) -> Path:
    root = tmp_path / "hybrid"
    for rel, src in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(src))
    return root


@pytest.mark.parametrize(
    "files,expect",
    [
        # an upward import: the mesh (geometry) importing the simulation
        ({"mesh.py": "from .simulation import Simulation\n", "simulation.py": ""}, "an upward import"),
        # hidden in a function, as lazy imports are
        ({"mesh.py": "def f():\n    from . import model\n", "model.py": ""}, "an upward import"),
        # a circle within one layer
        ({"scene.py": "from . import scenefile\n", "scenefile.py": "from .scene import Scene\n"}, "import circle"),
        # MuJoCo outside its door
        ({"render.py": "import mujoco\n"}, "imports mujoco outside"),
        # a module nobody placed
        ({"newthing.py": ""}, "in no layer"),
    ],
)
def test_the_checker_catches_what_it_is_for(tmp_path, files, expect):
    root = _fake_package(tmp_path, {"__init__.py": "", **files})
    found = violations(root)
    assert any(expect in v for v in found), found


def test_the_checker_accepts_downward_and_sideways_imports(tmp_path):
    root = _fake_package(
        tmp_path,
        {
            "__init__.py": "from .simulation import Simulation\n",
            "simulation.py": "from .model import Model\nfrom . import step\n",
            "step.py": "from .terms import base\n",
            "model.py": "",
            "terms/__init__.py": "from .base import Term\n",
            "terms/base.py": "",
            "rigid/__init__.py": "import mujoco\n",
        },
    )
    assert violations(root) == []


# what a warm `hybrid run` would otherwise pay to import before it needs it (CPU s, measured
# alone: matplotlib 0.45, scipy.spatial 0.3, scipy.sparse 0.2, mujoco 0.1); scipy itself
# numba imports
HEAVY_LATER = ("matplotlib", "mujoco", "scipy.spatial", "scipy.sparse", "trimesh")


@pytest.mark.parametrize("module", ["hybrid", "hybrid.cli"])
def test_importing_the_package_or_the_command_line_leaves_the_heavy_libraries_for_later(module):
    import subprocess
    import sys

    code = f"import sys, {module}; print(sorted(m for m in {HEAVY_LATER!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
