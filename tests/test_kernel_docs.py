"""Every compiled step kernel says what it reads and writes, in MuJoCo Warp's convention:
`# Model:`, `# Data in:` and `# Data out:` in its docstring (`# Data in/out:` counts for
both; `# Scratch:` where it has some; "none" where it reads nothing of one kind)."""

from __future__ import annotations

import gc
import importlib
import pkgutil
import re

from numba.core.registry import CPUDispatcher

import hybrid
from hybrid.kernel import FLAGS

#: the step path's kernels that do not say it yet (hybrid/step.py, coupling.py, implicit.py,
#: implicit_matrix.py, simulation.py, being refactored): their comments come with that work,
#: which empties this set; the test fails on a name here that says it now or no longer exists
_PENDING_STEP_PATH = {
    "hybrid.implicit._gather",
    "hybrid.implicit._merit",
    "hybrid.implicit._product",
    "hybrid.implicit._residual",
    "hybrid.implicit._scatter",
    "hybrid.implicit._scatter_add",
    "hybrid.implicit._solve",
    "hybrid.implicit._trial",
    "hybrid.implicit._volume_gradient",
    "hybrid.implicit.implicit_pressure",
    "hybrid.implicit.newton_caches",
    "hybrid.implicit.newton_product",
    "hybrid.implicit_matrix._cholesky",
    "hybrid.implicit_matrix._g",
    "hybrid.implicit_matrix._gt",
    "hybrid.implicit_matrix._invert",
    "hybrid.implicit_matrix._true_residual",
    "hybrid.implicit_matrix.assemble",
    "hybrid.implicit_matrix.cg_update",
    "hybrid.implicit_matrix.dot",
    "hybrid.implicit_matrix.lower_solve",
    "hybrid.implicit_matrix.matrix_product",
    "hybrid.implicit_matrix.sgs_sweep",
    "hybrid.implicit_matrix.split_cg",
    "hybrid.implicit_matrix.upper_solve",
}
STEP_PATH = (
    "hybrid.step",
    "hybrid.loop",
    "hybrid.coupling",
    "hybrid.implicit",
    "hybrid.implicit_matrix",
    "hybrid.simulation",
)
TAGS = (re.compile(r"# Model:"), re.compile(r"# Data in(/out)?:"), re.compile(r"# Data (in/)?out:"))


def documented(doc: str | None) -> bool:
    return all(tag.search(doc or "") for tag in TAGS)


def step_kernels() -> dict:
    """Every kernel of the package by qualified name: the numba functions that
    `hybrid.kernel.kernel` and `kernel_twin` made, found among all live objects once
    every module is imported (also those no module name binds); they are compiled
    without reference counting (`FLAGS`), which `hybrid.kernel.jit`'s helpers outside
    the step keep."""
    for info in pkgutil.walk_packages(hybrid.__path__, "hybrid."):
        if info.name != "hybrid.__main__":  # runs the command line
            importlib.import_module(info.name)
    return {
        f"{d.py_func.__module__}.{d.py_func.__qualname__}": d
        for d in gc.get_objects()
        if isinstance(d, CPUDispatcher)
        and d.py_func.__module__.startswith("hybrid.")
        and d.targetoptions.get("_nrt") is False
    }


def test_every_kernel_says_what_it_reads_and_writes():
    assert FLAGS["_nrt"] is False  # what tells a kernel from a helper
    kernels = step_kernels()
    # the search finds them: the terms' and the step's, serial and parallel builds
    assert len(kernels) > 100
    assert {"hybrid.terms.springs.add_applied", "hybrid.terms.volume._volume_update_parallel"} <= set(kernels)
    missing = {name for name, d in kernels.items() if not documented(d.py_func.__doc__)}
    assert not missing - _PENDING_STEP_PATH, sorted(missing - _PENDING_STEP_PATH)
    # the set cannot go stale: each name is a kernel of the step path still without its comments
    assert not _PENDING_STEP_PATH - missing, sorted(_PENDING_STEP_PATH - missing)
    assert all(name.rpartition(".")[0] in STEP_PATH for name in _PENDING_STEP_PATH)


def test_the_check_reads_the_convention():
    assert documented("x.\n    # Model: a   # Data in: b\n    # Data out: c\n")
    assert documented("# Model: none   # Data in/out: vert_pos")
    assert not documented("# Model: a\n# Data out: c")  # no inputs named
    assert not documented("Model: a, Data in: b, Data out: c")
    assert not documented(None)
