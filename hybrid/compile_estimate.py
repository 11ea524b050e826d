"""What a first run compiles and how long the command line says it will take: the estimate
the compile notice announces (`hybrid.kernel.compile_notice`), by kind of compile, from this
machine's record of its last compiles, else the package's figures (`COMPILE_ESTIMATE_S`).
"""

from __future__ import annotations

from .integrators import is_implicit
from .kernel import has_cached_build, measured_compile_s, record_compile_s

__all__ = ["compile_estimate", "COMPILE_ESTIMATE_S"]


def compile_estimate(scene):
    """The compile notice's estimate (`hybrid.kernel.compile_notice`), given when the step loop
    compiles: a first run's whole compile, else that other build's (implicit, multi-core). It is
    this machine's last compiles of that kind (`hybrid.kernel.measured_compile_s`), else the
    package's figure; on_compiled records the compile announced."""
    from .implicit import implicit_start_forces, implicit_step
    from .loop import run_steps, steps_between
    from .loop_compile import loop_build

    implicit = is_implicit(scene.integrator)
    loop = (run_steps, steps_between)
    solves = (implicit_start_forces, implicit_step)
    first = not has_cached_build(steps_between)
    announced = []

    def estimate(dispatcher, arg_types):
        # announced when the loop compiles, or implicit Euler's solve (compiled apart, when the
        # simulation is made): the scene's helpers before them (a second at most) are counted and
        # said at the end, so that a refusal between them is one line
        solve = any(dispatcher is k for k in solves)
        in_loop = any(dispatcher is k for k in loop)
        if first and (solve or in_loop):
            kind = "first run, " + ("implicit" if implicit else "rigid" if scene.rigid is not None else "membrane")
        elif in_loop and arg_types is not None:
            kind = "loop build, " + loop_build(arg_types)
        elif solve:
            kind = "implicit solve"
        else:
            return None
        announced.append(kind)
        return measured_compile_s(kind) or COMPILE_ESTIMATE_S[kind]

    def on_compiled(cpu_s):
        if announced:
            record_compile_s(announced[0], cpu_s)

    return estimate, on_compiled


#: a compile's CPU seconds on a machine that has recorded none: a first run's (membrane only,
#: with a rigid part, implicit Euler), another build of the step loop once one is cached
#: (`hybrid.loop_compile.loop_build`), implicit Euler's solve (compiled apart) once the loop is; a first
#: run's counts its helper process's too (`hybrid.calls.compile_elsewhere`). Measured by the notice on
#: an empty NUMBA_CACHE_DIR, 2 cores, --duration 0.01 or 0.02 --no-record, for 0.20: `hybrid run`
#: 32.8, 32.0, 35.1; `hybrid run membrane_demo` 27.6; `hybrid run --set integrator=implicit_euler --set
#: dt_s=0.01` 85.3, and 44.6 after `hybrid run` (the implicit solve; 104.7 and 60.2 before 0.20.2
#: compiled `assemble` once); `membrane_demo --set
#: mesh.level=6 --set dt_s=1e-4` after `hybrid run` (the multi-core build) 27.0. The serial build
#: after an implicit first run is 0.12's (10.4, 11.4): every solver now steps through one build.
COMPILE_ESTIMATE_S = {
    "first run, membrane": 28,
    "first run, rigid": 32,
    "first run, implicit": 85,
    "loop build, serial": 11,
    "loop build, parallel": 27,
    "implicit solve": 45,
}
