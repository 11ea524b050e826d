"""How the step's kernels are compiled.

Every step kernel is compiled without reference counting (`_nrt=False`)
and with the fast-math flags that keep NaN and infinity visible (`FAST`):
the step allocates nothing, and the atomic reference counts numba would
otherwise add around each call cost about 0.5 us per call. The per-point
passes that dominate large meshes are also compiled a second time from the
same source with `parallel=True` (their `prange` loops then run on all
cores); the model picks that build when the mesh has at least
`PARALLEL_MIN_VERTS` points, below which the threads cost more than they save.
"""

from __future__ import annotations

import types

import numba
from numba import njit

__all__ = ["FAST", "FLAGS", "kernel", "kernel_twin", "PARALLEL_MIN_VERTS", "use_parallel"]

# Fast-math without the flags that assume no NaN or infinity: fused
# multiply-adds and reciprocals, but the divergence check still sees NaN.
FAST = {"contract", "arcp", "nsz", "afn"}
FLAGS = dict(cache=True, error_model="numpy", _nrt=False, fastmath=FAST)
PARALLEL_MIN_VERTS = 2000


def kernel(fn=None, **extra):
    """`@kernel`: compile a step kernel with the step's flags."""
    if fn is None:
        return lambda f: njit(**FLAGS, **extra)(f)
    return njit(**FLAGS, **extra)(fn)


def kernel_twin(fn, **extra):
    """(serial, parallel) builds of one kernel source. The parallel copy gets its
    own qualified name so that the two builds keep separate on-disk caches."""
    par = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_parallel", fn.__defaults__,
                             fn.__closure__)
    par.__qualname__ = fn.__qualname__ + "_parallel"
    par.__doc__ = fn.__doc__
    return njit(**FLAGS, **extra)(fn), njit(**FLAGS, parallel=True, **extra)(par)


def use_parallel(nvert: int) -> bool:
    """Whether a mesh of nvert points runs the parallel build."""
    return nvert >= PARALLEL_MIN_VERTS and numba.get_num_threads() > 1
