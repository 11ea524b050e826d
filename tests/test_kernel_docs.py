"""Every compiled step kernel says what it reads and writes, in MuJoCo Warp's convention:
`# Model:`, `# Data in:` and `# Data out:` in its docstring (`# Data in/out:` counts for
both; `# Scratch:` where it has some; "none" where it reads nothing of one kind)."""

from __future__ import annotations

import gc
import importlib
import inspect
import pkgutil
import re

from numba.core.registry import CPUDispatcher

import hybrid
from hybrid.kernel import FLAGS

TAGS = (re.compile(r"# Model:"), re.compile(r"# Data in(/out)?:"), re.compile(r"# Data (in/)?out:"))


def documented(doc: str | None) -> bool:
    return all(tag.search(doc or "") for tag in TAGS)


def compiled_functions() -> dict:
    """Every numba function of the package by qualified name, found among all live objects
    once every module is imported (also those no module name binds)."""
    for info in pkgutil.walk_packages(hybrid.__path__, "hybrid."):
        if info.name != "hybrid.__main__":  # runs the command line
            importlib.import_module(info.name)
    found = {}
    for d in gc.get_objects():
        try:  # a weak proxy whose object is gone raises on any look
            is_compiled = isinstance(d, CPUDispatcher)
        except ReferenceError:
            continue
        if is_compiled and d.py_func.__module__.startswith("hybrid."):
            found[f"{d.py_func.__module__}.{d.py_func.__qualname__}"] = d
    return found


def step_kernels() -> dict:
    """Every kernel of the package by qualified name: the numba functions that
    `hybrid.kernel.kernel` and `kernel_twin` made, found among all live objects once
    every module is imported (also those no module name binds); they are compiled
    without reference counting (`FLAGS`), which `hybrid.kernel.jit`'s helpers outside
    the step keep."""
    return {name: d for name, d in compiled_functions().items() if d.targetoptions.get("_nrt") is False}


def test_every_kernel_says_what_it_reads_and_writes():
    assert FLAGS["_nrt"] is False  # what tells a kernel from a helper
    kernels = step_kernels()
    # the search finds them: the terms' and the step's, serial and parallel builds
    assert len(kernels) > 100
    assert {"hybrid.terms.springs.add_applied", "hybrid.terms.volume._volume_update_parallel"} <= set(kernels)
    missing = {name for name, d in kernels.items() if not documented(d.py_func.__doc__)}
    assert not missing, sorted(missing)


def test_the_check_reads_the_convention():
    assert documented("x.\n    # Model: a   # Data in: b\n    # Data out: c\n")
    assert documented("# Model: none   # Data in/out: vert_pos")
    assert not documented("# Model: a\n# Data out: c")  # no inputs named
    assert not documented("Model: a, Data in: b, Data out: c")
    assert not documented(None)


def test_every_compiled_function_sets_its_arithmetic_flags():
    # numba lets a function that does not set `fastmath` inherit its caller's: a helper
    # called both from the step (fast arithmetic) and from Python would then round
    # differently by which build reached the cache first, and a run's bits would depend
    # on the order scenes were first run in
    found = compiled_functions()
    assert len(found) > len(step_kernels())  # the helpers outside the step are found too
    unset = sorted(name for name, d in found.items() if "fastmath" not in d.targetoptions)
    assert not unset, unset


def test_no_kernel_takes_more_than_twelve_parameters():
    # the step path passes packs (`MembraneArrays`, `MembraneState`, `RigidPack`, tuples of
    # flags or scratch), not long argument lists: a long list is where a new term's
    # argument goes in at the wrong place, and every call site must change with it
    kernels = step_kernels()
    assert len(kernels) > 100  # the finder sees the whole step (136 kernels when written)
    long = sorted(
        f"{name}: {len(inspect.signature(d.py_func).parameters)}"
        for name, d in kernels.items()
        if len(inspect.signature(d.py_func).parameters) > 12
    )
    assert not long, long
