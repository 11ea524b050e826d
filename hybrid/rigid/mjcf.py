"""Where a rigid model comes from: MJCF files (ours, "trunk", or a user's, read and
never written) and models an installed package builds in memory ("myo_sim:myotorso"),
each loaded into an editable `mujoco.MjSpec`; compiling one with a readable error;
and where MuJoCo's warnings go.
"""

from __future__ import annotations

import logging
from pathlib import Path

import mujoco

from hybrid.errors import RigidError, SceneError
from hybrid.scene import Scene
from hybrid.scenefile import packaged_model

_mujoco_log = logging.getLogger("hybrid.mujoco")


def _log_mujoco_warning(message: str) -> None:
    _mujoco_log.warning("MuJoCo: %s", message)


# MuJoCo's default warning handler prints and appends to MUJOCO_LOG.TXT in the working
# folder; its warnings go to the logger "hybrid.mujoco" instead (printed on stderr
# unless logging is set up otherwise), unless the program has its own handler
if mujoco.get_mju_user_warning() is None:
    mujoco.set_mju_user_warning(_log_mujoco_warning)

#: The packaged trunk model (spine fixed to the world, two hinged ribs, sternum spring).
TRUNK_XML: Path = packaged_model("trunk.xml")

#: MJCF names a scene may use instead of a path.
BUILTIN_MJCF = {"trunk": TRUNK_XML, "builtin:trunk": TRUNK_XML}


def _myo_sim_spec(name: str) -> mujoco.MjSpec:
    import myo_sim

    return myo_sim.load_spec(name)


#: Models built in memory by an installed package instead of read from a file:
#: rigid.mjcf = "SCHEME:NAME" -> (import name, what to install, builder of an editable
#: MjSpec from NAME). The package's files are only read; our sites and masses are added
#: to the returned MjSpec. "myo_sim:myotorso" is MyoSuite's torso (myo_sim.load_spec).
PACKAGE_MJCF = {"myo_sim": ("myo_sim", "pip install 'hybrid[myo]' (or myo-sim)", _myo_sim_spec)}


def load_spec(path_or_xml: str | Path) -> mujoco.MjSpec:
    """Load an MJCF model into a `mujoco.MjSpec`.

    Parameters
    ----------
    path_or_xml : a path to an MJCF file, or the MJCF text itself (a string whose
        first non-blank character is '<').

    Raises
    ------
    RigidError : the file does not exist, or MuJoCo cannot parse it (the message
        names the file and carries MuJoCo's own message).
    """
    if isinstance(path_or_xml, str) and path_or_xml.lstrip().startswith("<"):
        try:
            return mujoco.MjSpec.from_string(path_or_xml)
        except ValueError as exc:
            raise RigidError(f"MJCF text: MuJoCo cannot parse it: {one_line(exc)}") from exc
    path = Path(path_or_xml)
    if not path.is_file():
        raise RigidError(f"MJCF file {str(path)!r}: no such file")
    try:
        return mujoco.MjSpec.from_file(str(path))
    except ValueError as exc:
        raise RigidError(f"MJCF file {str(path)!r}: MuJoCo cannot parse it: {one_line(exc)}") from exc


def one_line(exc: BaseException) -> str:
    """MuJoCo's message of `exc` on one line."""
    return " ".join(str(exc).split())


def compile_spec(spec: mujoco.MjSpec, label: str | None = None) -> mujoco.MjModel:
    """`spec.compile()`; RigidError naming `label` (by default the model's name) when
    MuJoCo cannot compile it."""
    try:
        return spec.compile()
    except ValueError as exc:
        label = f"model {spec.modelname!r}" if label is None else label
        raise RigidError(f"MJCF {label}: MuJoCo cannot compile it: {one_line(exc)}") from exc


def resolve_mjcf(scene: Scene) -> Path:
    """The MJCF file of `scene.rigid`: "trunk" / "builtin:trunk" is the packaged
    `models/trunk.xml`; anything else is a path, relative to the scene's folder."""
    mjcf = scene.rigid.mjcf
    if not isinstance(mjcf, (str, Path)) or not str(mjcf).strip():
        raise SceneError(f"rigid.mjcf: expected 'trunk' or the path of an MJCF file, received {mjcf!r}")
    if str(mjcf) in BUILTIN_MJCF:
        return BUILTIN_MJCF[str(mjcf)]
    if _package_model(str(mjcf)) is not None:
        raise RigidError(
            f"rigid.mjcf: {str(mjcf)!r} is built in memory by a package, it has no file; "
            f"use hybrid.rigid.load_rigid_spec"
        )
    path = scene.resolve(str(mjcf))
    if not path.is_file():
        raise RigidError(f"rigid.mjcf: no such file {str(path)!r}; expected 'trunk' or the path of an MJCF file")
    return path


def _package_model(mjcf: str) -> tuple[str, str] | None:
    scheme, sep, name = mjcf.partition(":")
    return (scheme, name) if sep and scheme in PACKAGE_MJCF else None


def load_rigid_spec(scene: Scene) -> tuple[mujoco.MjSpec, str, Path | str]:
    """(MjSpec, label, source) of `scene.rigid.mjcf`: a file read by MuJoCo (source its
    Path), or "SCHEME:NAME" of `PACKAGE_MJCF` built by its package (source the string).
    Raises RigidError naming the package and how to install it when it is absent."""
    mjcf = scene.rigid.mjcf
    pkg = _package_model(str(mjcf)) if isinstance(mjcf, (str, Path)) else None
    if pkg is None:
        path = resolve_mjcf(scene)
        return load_spec(path), path.name, path
    scheme, name = pkg
    module, install, builder = PACKAGE_MJCF[scheme]
    try:
        __import__(module)
    except ImportError as exc:
        raise RigidError(
            f"rigid.mjcf {str(mjcf)!r}: needs the package {module!r}, which is not installed ({exc}); {install}"
        ) from exc
    try:
        spec = builder(name)
    except (ValueError, KeyError) as exc:
        raise RigidError(f"rigid.mjcf {str(mjcf)!r}: {module} cannot build {name!r}: {one_line(exc)}") from exc
    return spec, str(mjcf), str(mjcf)
