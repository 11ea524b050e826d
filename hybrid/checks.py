"""Value checks shared by the scene file reader and the terms' compile functions.

Each check takes `where` (the culprit as the user wrote it: ``breathing.toml:
forces[2].stiffness_n_per_m`` from a file, ``forces['muscle'].stiffness_n_per_m``
from Python), the value, and raises a one-line `SceneError` saying what was
expected and what was received; otherwise it returns the value normalised
(floats, tuples). A bool is never a number.
"""

from __future__ import annotations

import math
import numbers

from .errors import SceneError

__all__ = ["fail", "show", "is_number", "number", "integer", "text", "plain_name", "boolean", "vec3", "vec3_list"]


# Physical ranges of the inputs: far beyond any body a scene describes, small
# enough that their products (force = stiffness * length, pressure = force /
# area, steps = duration / dt) stay finite in float64.
MAX_MASS_KG = 1e6
MAX_STIFFNESS_N_PER_M = 1e12
MAX_LENGTH_M = 1e3
MAX_DT_S = 1e3  # the stability study probes steps of seconds on soft bodies
MAX_DURATION_S = 1e9
MAX_MODULUS_PA = 1e12  # a bulk modulus (diamond's is 4.4e11 Pa)
MAX_DRAG_N_S_PER_M3 = 1e12
MAX_SPEED_M_S = 3e8  # the runaway guard's speed: at most about light's
#: the longest name a run's files take ("NAME.png", and the fresh name it is written under
#: first, 23 characters more, within the 255 bytes a file name may have)
MAX_NAME_CHARS = 200
#: the most points a mesh may have, checked before any array is allocated: building and
#: checking a mesh takes about `MESH_BYTES_PER_POINT` a point (1.9 kB measured from mesh
#: level 10 to 12: 323 -> 771 MB of peak memory for 80 k -> 319 k points), so 2^21 points
#: about 4 GB (mesh level 14, 1.28 million points, fits; level 16 would take 10 GB)
MAX_POINTS = 2**21
MESH_BYTES_PER_POINT = 2000


def available_bytes() -> int | None:
    """The memory this process may still take: the smaller of the system's available
    memory and the address-space limit (None when neither is known)."""
    import resource

    found = []
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        found.append(soft)
    return min(found) if found else None


def mesh_points(where: str, npoint: int, how: str = "", *, error=None) -> int:
    """`npoint` (a mesh about to be built, `how` says from what) checked before any array
    is allocated: at most `MAX_POINTS` and what the memory available holds at
    `MESH_BYTES_PER_POINT`; else one line naming the count and the limit (`error`: the
    exception class, SceneError by default)."""
    limit, why = MAX_POINTS, "MAX_POINTS"
    avail = available_bytes()
    if avail is not None and avail // MESH_BYTES_PER_POINT < limit:
        limit, why = avail // MESH_BYTES_PER_POINT, f"what the {avail / 1e9:.1f} GB of memory available hold"
    if npoint > limit:
        need = npoint * MESH_BYTES_PER_POINT / 1e9
        raise (error or SceneError)(
            f"{where}: {how}{npoint} points, about {need:.3g} GB to build and check; "
            f"expected at most {limit} points ({why})"
        )
    return npoint


def fail(where: str, msg: str):
    raise SceneError(f"{where}: {msg}" if where else msg)


def show(v) -> str:
    """A value as a user wrote it (TOML spelling for booleans and tables), shortened."""
    if isinstance(v, bool):
        s = "true" if v else "false"
    elif isinstance(v, str):
        s = repr(v)
    elif isinstance(v, dict):
        s = "a table {" + ", ".join(f"{k} = {show(x)}" for k, x in v.items()) + "}"
    else:
        s = repr(v)
    return s if len(s) <= 80 else s[:77] + "..."


def is_number(v) -> bool:
    """An int or a float, numpy's scalars too (np.float32(1e-3) is a step); never a bool."""
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and type(v).__name__ != "bool_"


def number(where, v, *, lo=None, lo_open=True, hi=None, hi_open=True) -> float:
    """A finite number, optionally within (lo, hi) (open or closed ends)."""
    if lo is None and hi is None:
        want = "a finite number"
    elif hi is None:
        want = f"a number {'>' if lo_open else '>='} {lo:g}"
    else:
        want = f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    ok = is_number(v) and math.isfinite(v)
    if ok and lo is not None:
        ok = v > lo if lo_open else v >= lo
    if ok and hi is not None:
        ok = v < hi if hi_open else v <= hi
    if not ok:
        fail(where, f"expected {want}, received {show(v)}")
    return float(v)


def positive(where, v, hi, unit="") -> float:
    """A finite number > 0 and <= hi: the lower bound checked first, so that its
    message stays "expected a number > 0"; the physical upper bound then."""
    x = number(where, v, lo=0)
    if x > hi:
        fail(where, f"expected a number > 0 and <= {hi:g}{unit} (a physical bound), received {show(v)}")
    return x


def integer(where, v, *, lo, hi=None) -> int:
    """An integer >= lo (and <= hi)."""
    if not (isinstance(v, int) and not isinstance(v, bool) and v >= lo and (hi is None or v <= hi)):
        fail(where, f"expected an integer {f'in {lo}..{hi}' if hi is not None else f'>= {lo}'}, received {show(v)}")
    return int(v)


def text(where, v, choices=None) -> str:
    if not isinstance(v, str) or (choices is not None and v not in choices):
        want = f"one of {list(choices)}" if choices is not None else "a string"
        fail(where, f"expected {want}, received {show(v)}")
    if "\x00" in v:  # file names and the recording's strings cannot hold it
        fail(where, f"expected text without NUL characters, received {show(v)}")
    return v


def plain_name(where, v) -> str:
    """A name that is only a name (a run's folder is runs/<name> without --out): not
    empty, no path separator, no '..', no NUL, not '.'."""
    if not isinstance(v, str):
        fail(where, f"expected a string, received {show(v)}")
    why = (
        f"has {len(v)} characters, more than {MAX_NAME_CHARS}"
        if len(v) > MAX_NAME_CHARS
        else "is empty"
        if not v.strip()
        else "holds a NUL character"
        if "\0" in v
        else "holds a path separator"
        if "/" in v or "\\" in v
        else "holds '..'"
        if ".." in v
        else "is '.'"
        if v == "."
        else None
    )
    if why is not None:
        fail(
            where,
            f"expected a plain name (the folder runs/<name> when --out is not given), received "
            f"{show(v) if len(v) > MAX_NAME_CHARS else repr(v)}, which {why}"
            + ("" if len(v) > MAX_NAME_CHARS else "; choose the folder with --out"),
        )
    return v


def boolean(where, v) -> bool:
    if not isinstance(v, bool):
        fail(where, f"expected true or false, received {show(v)}")
    return v


def vec3(where, v) -> tuple:
    """Three finite numbers, as a tuple of floats."""
    if not (isinstance(v, (list, tuple)) and len(v) == 3 and all(is_number(x) and math.isfinite(x) for x in v)):
        fail(where, f"expected a 3-vector of finite floats, received {show(v)}")
    return tuple(float(x) for x in v)


def vec3_list(where, v) -> tuple:
    if not (isinstance(v, (list, tuple)) and v):
        fail(where, f"expected a list of 3-vectors, received {show(v)}")
    return tuple(vec3(f"{where}[{k}]", x) for k, x in enumerate(v))
