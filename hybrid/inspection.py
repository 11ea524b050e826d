"""`hybrid inspect SCENE | MJCF [--json]`: what a scene or a rigid model holds, without
running it.

For an MJCF file (`*.xml`, `*.mjcf`, "trunk", or a package model "myo_sim:myotorso"):
its bodies with their world positions at `qpos0`, joints, actuators, keyframes, timestep
and integrator (`hybrid.rigid.describe`). For a scene (a name or a `.toml` file, with
`--set` and `--without` as `hybrid run`): its membrane (points, area, volume), regions
with their point counts and areas, terms, nailed points, rigid links, the time step and
the per-point stability estimate (`Model.dt_stable_s`), and its rigid model as compiled
for the run (with the scene's control keys, attachment sites and link masses).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .errors import SceneError

__all__ = ["inspect_source", "format_report", "is_mjcf_source"]

_MJCF_SUFFIXES = (".xml", ".mjcf")


def is_mjcf_source(source: str) -> bool:
    """Whether `source` names a rigid model rather than a scene."""
    text = str(source)
    if text.lower().endswith(_MJCF_SUFFIXES) or text in ("trunk", "builtin:trunk"):
        return True
    scheme, sep, _ = text.partition(":")
    return bool(sep) and scheme == "myo_sim"


def _mjcf_report(source: str) -> dict:
    from .rigid.describe import describe_model, describe_spec

    if source.partition(":")[0] == "myo_sim":
        from .rigid import load_rigid_spec
        from .rigid.mjcf import compile_spec
        from .scene import Masses, Rigid, Scene

        spec, label, _ = load_rigid_spec(Scene(masses=Masses(total_kg=1.0), rigid=Rigid(source)))
        return {"kind": "mjcf", "source": source, "model": describe_model(compile_spec(spec, label))}
    if not source.lower().endswith(_MJCF_SUFFIXES) or Path(source).is_file():
        return {"kind": "mjcf", "source": source, "model": describe_spec(source)}
    raise SceneError(f"MJCF file {source!r}: no such file")


def _scene_report(source, overrides, without) -> dict:
    from .mesh import vertex_area, volume
    from .model import compile_scene
    from .resolve import resolve_scene
    from .terms import Nailed

    scene = resolve_scene(source, overrides=overrides, without=without)
    model = compile_scene(scene)
    mesh = model.mesh
    area = vertex_area(mesh.vert_pos, mesh.face_vert)

    def region(idx) -> dict:
        idx = np.asarray(idx)
        return {"points": int(idx.size), "area_m2": float(area[idx].sum())}

    report = {
        "kind": "scene",
        "source": str(source),
        "name": scene.name,
        "formulation": scene.formulation,
        "dt_s": model.dt_s,
        "dt_from": "scene" if scene.dt_s is not None else "mjcf" if model.rigid is not None else "default",
        "dt_stable_s": model.dt_stable_s if math.isfinite(model.dt_stable_s) else None,
        "membrane": {
            "points": int(mesh.nvert),
            "faces": int(mesh.face_vert.shape[0]),
            "area_m2": float(area.sum()),
            "volume_m3": float(volume(mesh.vert_pos, mesh.face_vert)),
            "mass_kg": float(model.arrays.vert_mass.sum()),
        },
        "regions": {name: region(idx) for name, idx in model.regions.items()},
        "terms": [
            {"name": t.name, "section": t.section, "type": t.toml_type} for t in (*scene.forces, *scene.constraints)
        ],
        "nails": [
            {"name": c.name, **region(_select(model, c.region, f"constraints[{c.name!r}].region"))}
            for c in scene.constraints
            if isinstance(c, Nailed)
        ],
        "links": [],
    }
    if model.rigid is not None:
        from .rigid.describe import describe_model

        rig = model.rigid
        for link in scene.rigid.links:
            idx = _select(model, link.region, f"rigid.links[{link.name!r}].region")
            report["links"].append(
                {
                    "name": link.name,
                    "body": rig.link_body[list(rig.link_vert).index(idx[0])] if idx.size else link.body,
                    **region(idx),
                }
            )
        from .rigid.held_volumes import held_volumes_gain
        from .rigid.modes import rigid_modes

        modes = rigid_modes(rig.model)
        gain = held_volumes_gain(model)
        report["rigid"] = {
            "mjcf": str(scene.rigid.mjcf),
            "settings": rig.settings(),
            "model": describe_model(rig.model),
            "dt_stable_s": modes.dt_stable_s if math.isfinite(modes.dt_stable_s) else None,
            "stable_step": modes.line(model.dt_s),
            "held_volumes_gain": None if gain is None else {"open": gain.open, "occluded": gain.occluded},
            "held_volumes": None if gain is None else gain.line(),
        }
    return report


def _select(model, sel, what) -> np.ndarray:
    from .regions import select

    mesh = model.mesh
    return select(
        sel, mesh.vert_pos, name=what, regions=model.regions, border_vert=mesh.border_vert, face_vert=mesh.face_vert
    )


def inspect_source(source: str | None, *, overrides=(), without=()) -> dict:
    """The report of a scene or an MJCF (module docstring), JSON values only.
    Raises SceneError / RigidError (one line) for what cannot be read."""
    if source is not None and is_mjcf_source(source):
        if overrides or without:
            raise SceneError(f"--set / --without: apply to a scene, not to the MJCF model {source!r}")
        return _mjcf_report(str(source))
    return _scene_report(source, overrides, without)


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def _model_lines(m: dict) -> list[str]:
    lines = [
        f"rigid model: timestep {m['timestep_s']:g} s, integrator {m['integrator']}, gravity "
        f"{_vec(m['gravity_m_s2'])} m/s^2, nq {m['nq']}, nv {m['nv']}, nu {m['nu']}",
        f"bodies ({len(m['bodies'])}; world position at qpos0, m):",
    ]
    lines += [
        f"  {b['name'] or '(unnamed)'}  parent {b['parent']}  {b['mass_kg']:.4g} kg  at {_vec(b['pos_m'])}"
        for b in m["bodies"]
    ]
    lines.append(f"joints ({len(m['joints'])}):")
    lines += [
        f"  {j['name'] or '(unnamed)'}  {j['type']} on {j['body']}  qpos0 {_vec(j['qpos0'])}"
        + (f"  range {_vec(j['range'])}" if j["range"] else "")
        for j in m["joints"]
    ]
    lines.append(f"actuators ({len(m['actuators'])}):")
    lines += [
        f"  {a['name'] or '(unnamed)'}  {a['target']}" + (f"  ctrl {_vec(a['ctrlrange'])}" if a["ctrlrange"] else "")
        for a in m["actuators"]
    ]
    lines.append(
        f"keyframes ({len(m['keyframes'])}): " + (", ".join(k["name"] or "(unnamed)" for k in m["keyframes"]) or "none")
    )
    return lines


def format_report(r: dict) -> str:
    """The report as text for a terminal."""
    if r["kind"] == "mjcf":
        return "\n".join([f"MJCF {r['source']}", *_model_lines(r["model"])])
    mem = r["membrane"]
    stable = "none (no stiffness)" if r["dt_stable_s"] is None else f"{r['dt_stable_s']:.3g} s"
    if r["dt_stable_s"] is not None and r["dt_s"] > r["dt_stable_s"]:
        stable += " (the step is larger: expect a divergence; set dt_s below it)"
    lines = [
        f"scene {r['name']} ({r['formulation']}) from {r['source']}",
        f"step: dt {r['dt_s']:g} s (from the {r['dt_from']}); stable-step estimate {stable}",
        f"membrane: {mem['points']} points, {mem['faces']} faces, area {mem['area_m2']:.4g} m^2, volume "
        f"{mem['volume_m3']:.4g} m^3, mass {mem['mass_kg']:.4g} kg",
        f"regions ({len(r['regions'])}):",
    ]
    lines += [f"  {k}: {v['points']} points, {v['area_m2']:.4g} m^2" for k, v in r["regions"].items()]
    lines.append(f"terms ({len(r['terms'])}):")
    lines += [f"  {t['name']} ({t['section']}: {t['type']})" for t in r["terms"]]
    lines.append(f"nails ({len(r['nails'])}):")
    lines += [f"  {n['name']}: {n['points']} points, {n['area_m2']:.4g} m^2" for n in r["nails"]]
    lines.append(f"links ({len(r['links'])}):")
    lines += [f"  {k['name']} -> {k['body']}: {k['points']} points, {k['area_m2']:.4g} m^2" for k in r["links"]]
    if "rigid" in r:
        s = r["rigid"]["settings"]
        changed = ", ".join(
            f"{k} {s[k]}" for k in ("keyframe", "fixed", "welded", "held", "locked", "driven") if s.get(k)
        )
        lines.append(
            f"rigid: {r['rigid']['mjcf']}; integrator {s['integrator']} (from the "
            f"{s['integrator_from']}); MJCF timestep {s['mjcf_timestep_s']:g} s" + (f"; {changed}" if changed else "")
        )
        rigid_stable = r["rigid"]["stable_step"]
        if r["rigid"]["dt_stable_s"] is not None and r["dt_s"] > r["rigid"]["dt_stable_s"]:
            rigid_stable += " (the step is larger: expect a divergence; set dt_s below it, or damp the mode's joints)"
        lines.append(rigid_stable)
        if r["rigid"]["held_volumes"] is not None:
            lines.append(r["rigid"]["held_volumes"])
        lines += _model_lines(r["rigid"]["model"])
    return "\n".join(lines)


def main_inspect(args) -> int:
    """`hybrid inspect` (hybrid.cli): prints the report, as JSON with --json."""
    report = inspect_source(args.source, overrides=args.set or (), without=args.without or ())
    print(json.dumps(report, indent=1) if args.json else format_report(report))
    return 0
