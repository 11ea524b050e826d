"""`hybrid study respiratory [SCENE] --out DIR [--small]`: a scene with lungs
(`hybrid.terms.lungs`) examined as a respiratory physiologist examines a subject.

1. **Passive respiratory system.** The muscles relaxed (every `muscle_fibres` term's
   tension 0, no `rigid.ctrl`), the airway-opening pressure raised by a step; at the
   new equilibrium (flow stopped) the respiratory system's compliance C_rs = dV/dP_ao,
   the chest wall's C_cw = dV/dP_pl (the pleural pressure's change) and the lungs'
   C_L = dV/d(P_ao - P_pl), which must be the law's own compliance.
2. **Relaxation, tau = R C.** The same step with the airway resistance raised to
   `RELAXATION_RESISTANCE` (so that the volume's slow mode stands apart from the
   membrane's and the ribs' fast ones) under implicit Euler: the volume's approach to
   its new equilibrium (less a control run without the step: the scene's own drift),
   fitted by V_inf (1 - a exp(-t / tau)) from `RELAXATION_FIT_FROM_S` on, against R
   times the compliance of the same run (V_inf over the step).
3. **Quiet breathing**: the scene as it is, its last breath's tidal volume, pleural
   pressure at end expiration and at end inspiration, transdiaphragmatic pressure swing,
   dome (apex) descent, rib lift, work of breathing and the first inspiration's volume
   shares (abdomen, pulmonary and abdominal rib cage), each against its band for an
   adult in quiet breathing (`BANDS`; sources in docs/lungs.md).
4. **Twitch**: the airway occluded, the diaphragm's tension a single twitch (`twitch_tension`:
   it peaks at the contraction time `TWITCH_CONTRACTION_S` and relaxes): the ratio of the
   oesophageal (pleural) to the transdiaphragmatic pressure change at the latter's peak (band
   0.35-0.55, the ATS/ERS statement's normal values).
5. **The paradox** of a rib cage without its muscles: the upper ribs the cavity's wall rides on
   (the scene's own, as `breathing_lungs`'s; a scene without them is given the breathing
   trunk's pair, `upper_rib_scene`); the hinge angles of the upper and lower ribs at the end of
   inspiration, with the diaphragm alone and with the upper ribs' inspiratory muscles.

Writes DIR/respiratory.json, and DIR/respiratory.md and DIR/respiratory.png
(`hybrid.studies.respiratory_report`). What is a
prediction and what is not: nothing here is fitted; the bands are the adult's, and the
default trunk is smaller than an adult's (docs/lungs.md).
"""

from __future__ import annotations

import dataclasses
import fnmatch
import math
import time
from pathlib import Path

import numpy as np

from ..demo import UPPER_RIB_WALL_TOP_M, with_upper_ribs
from ..errors import SceneError
from ..outputs import write_text as _write_text
from ..resolve import resolve_scene
from ..run import RunFailed
from ..scene import Lungs
from ..schedule import Breathing, Constant, Table
from ..terms.fibres import MuscleFibres
from ..terms.lungs import CMH2O_PA
from .respiratory_report import markdown, plot
from .stability.report import write_json

__all__ = [
    "run",
    "study_scene",
    "passive_compliance",
    "relaxation",
    "quiet_breathing",
    "twitch",
    "paradox",
    "upper_rib_scene",
]

#: quiet breathing of a supine adult: (low, high) and the source (docs/lungs.md, PHYSIOLOGY)
BANDS = {
    "tidal_volume_l": (0.4, 0.6, "physiology textbooks"),
    "end_expiratory_pleural_pressure_cmh2o": (-6.0, -4.0, "about -5 cmH2O at FRC, textbooks"),
    "end_inspiratory_pleural_pressure_cmh2o": (-8.5, -7.0, "VT / C_L + R_aw Q (derived)"),
    "transdiaphragmatic_pressure_swing_cmh2o": (3.0, 8.0, "derived from the pleural and gastric swings"),
    "apex_descent_mm": (10.0, 25.0, "Boussuges et al. 2009, Chest 135:391"),
    "rib_lift_mm": (3.0, 5.0, "De Groote et al. 1997, J Appl Physiol 83:1531"),
    "work_of_breathing_j_per_l": (0.2, 1.0, "physiology texts; critical care reviews"),
    "abdomen_share": (0.52, 0.75, "supine, Aliverti et al. 2001, Ann Biomed Eng 29:60"),
    "pulmonary_rib_cage_share": (0.14, 0.33, "supine, Aliverti et al. 2001"),
    "abdominal_rib_cage_share": (0.11, 0.17, "supine, Aliverti et al. 2001"),
    "respiratory_system_compliance_l_per_cmh2o": (0.05, 0.17, "textbooks"),
    "twitch_pes_over_pdi": (0.35, 0.55, "ATS/ERS statement on respiratory muscle testing"),
}
#: the airway-opening pressure steps of the static compliance (cmH2O)
COMPLIANCE_STEPS_CMH2O = (2.0, 5.0)
#: the relaxation: airway resistance (cmH2O s/L), step (cmH2O), implicit Euler's step (s)
RELAXATION_RESISTANCE = 50.0
RELAXATION_STEP_CMH2O = 0.05
RELAXATION_DT_S = 5e-3
#: the fit starts after the fast modes (the membrane's and the ribs', tens of ms) have died
RELAXATION_FIT_FROM_S = 2.0
#: the twitch's contraction time (s), from the stimulus to the peak of the tension: the human
#: diaphragm's Pdi twitch under bilateral phrenic stimulation takes 91.8 ms at residual volume
#: and 57.7 ms at total lung capacity (J Appl Physiol 62:1893, 1987); the resting volume lies
#: between, and 80 ms is chosen there. (Until 0.22 the study stepped the tension up in 10 ms and
#: held it 0.1 s: Pdi then peaked 30-40 ms in, as the walls started to move, docs/lungs.md.)
TWITCH_CONTRACTION_S = 0.08
#: the twitch's tension sampled this often (s) for its `Table`
TWITCH_SAMPLE_S = 1e-3
#: the same contraction held at its peak this long (s) after the contraction time: the occluded
#: trunk's quasi-static split, without the walls' inertia (it settles within 0.6 s on the breathing
#: trunk at level 0: docs/lungs.md)
TWITCH_HELD_S = 1.0
#: the twitch's and the held contraction's pressures kept for the figure: every this many frames (2 ms)
TWITCH_CURVE_EVERY = 2


def _lungs_of(scene):
    for f in scene.forces:
        if isinstance(f, Lungs):
            return f
    raise SceneError(f"study respiratory: scene {scene.name!r} has no lungs; expected a scene with a lungs term")


def _with(scene, *, tension=None, **lung_changes):
    """`scene` with every muscle_fibres term's tension replaced by `tension` (when given)
    and the lungs term changed by `lung_changes`."""
    forces = []
    for f in scene.forces:
        if tension is not None and isinstance(f, MuscleFibres):
            f = dataclasses.replace(f, tension_n_per_m=tension)
        if isinstance(f, Lungs) and lung_changes:
            f = dataclasses.replace(f, **lung_changes)
        forces.append(f)
    rigid = scene.rigid
    if tension is not None and rigid is not None and rigid.ctrl:
        rigid = dataclasses.replace(rigid, ctrl={})
    return dataclasses.replace(scene, forces=tuple(forces), rigid=rigid)


def _trace(scene, duration_s, frame_dt_s, overrides=()):
    from .. import load, run

    sc = resolve_scene(dataclasses.replace(scene, duration_s=duration_s), overrides=overrides)
    return run(load(sc), duration_s, frame_dt_s=frame_dt_s)


def _step(p_cmh2o):
    """The airway-opening pressure stepped to p at once (within a microsecond)."""
    return Table((0.0, 1e-6), (0.0, p_cmh2o))


def passive_compliance(scene, step_cmh2o: float, duration_s: float) -> dict:
    """Study 1 at one step: the compliances (L/cmH2O) from the last 0.25 s's means."""
    relaxed = _with(scene, tension=Constant(0.0), airway_opening_pressure_cmh2o=_step(step_cmh2o))
    a = _trace(relaxed, duration_s, 0.01)["trace"].arrays()
    late = a["t_s"] >= duration_s - 0.25
    dv = float(np.mean(a["lung_volume_change_l"][late]))
    dppl = float(np.mean(a["pleural_pressure_cmh2o"][late]) - a["pleural_pressure_cmh2o"][0])
    lungs = _lungs_of(scene)
    law = lungs.lung_compliance_l_per_cmh2o or (1.0 / lungs.lung_elastance_cmh2o_per_l)
    out = {
        "step_cmh2o": step_cmh2o,
        "volume_change_l": dv,
        "pleural_pressure_change_cmh2o": dppl,
        "late_flow_max_l_per_s": float(np.max(np.abs(a["flow_l_per_s"][late]))),
        "respiratory_system_compliance_l_per_cmh2o": dv / step_cmh2o,
        "chest_wall_compliance_l_per_cmh2o": dv / dppl,
        "lung_compliance_l_per_cmh2o": dv / (step_cmh2o - dppl),
        "law_lung_compliance_l_per_cmh2o": law,
    }
    out.update(_compartments(a, late, dppl))
    return out


def _compartments(a: dict, late: np.ndarray, dppl: float) -> dict:
    """The chest wall's compartments (Konno & Mead) in a passive step: the rib cage's under the
    pleural pressure's change, the abdomen's under its own (the gastric pressure), and the
    occluded twitch's dPes / dPdi that two such compartments imply (below)."""
    if "rib_cage_pulmonary_volume_change_l" not in a:  # no rigid part: no rib cage
        return {}
    volume = {k: float(np.mean(a[f"{k}_volume_change_l"][late])) for k in ("rib_cage_pulmonary", "rib_cage_abdominal")}
    volume["abdomen"] = float(np.mean(a["abdomen_volume_change_l"][late]))
    dpga = float(np.mean(a["pressure_pa"][late]) - a["pressure_pa"][0]) / CMH2O_PA
    c_rc = (volume["rib_cage_pulmonary"] + volume["rib_cage_abdominal"]) / dppl
    c_ab = volume["abdomen"] / dpga
    return {
        "gastric_pressure_change_cmh2o": dpga,
        "compartment_volume_change_l": volume,
        "rib_cage_compliance_l_per_cmh2o": c_rc,
        "abdomen_compliance_l_per_cmh2o": c_ab,
        # an occluded twitch holds the lung's volume: the rib cage's change C_rc dPes matches the
        # abdomen's -C_ab dPga, so dPes / dPdi = C_ab / (C_ab + C_rc) when the diaphragm acts on the
        # rib cage through the pleural pressure alone (its insertional and appositional pulls left
        # out: Konno & Mead's two compartments; Konno & Mead 1968 find the abdomen about as compliant
        # as the rib cage in quiet breathing, which makes it about 0.5)
        "twitch_ratio_two_compartments": c_ab / (c_ab + c_rc),
    }


def relaxation(scene, duration_s: float, r: float = RELAXATION_RESISTANCE) -> dict:
    """Study 2 at airway resistance r (cmH2O s/L): the fitted time constant against R C. The
    step's response is the run with the step less a control run without it, as an experimenter
    subtracts a sham: a scene not quite at rest where it starts (the fitted trunk's lungs fill by
    0.7 mL over 30 s) would otherwise add its own drift to a response of a few mL."""
    from scipy.optimize import curve_fit

    volumes = []
    for step in (RELAXATION_STEP_CMH2O, 0.0):
        slow = _with(
            scene,
            tension=Constant(0.0),
            airway_resistance_cmh2o_s_per_l=r,
            rohrer_k2_cmh2o_s2_per_l2=0.0,
            airway_opening_pressure_cmh2o=_step(step),
        )
        a = _trace(slow, duration_s, 0.01, ("integrator=implicit_euler", f"dt_s={RELAXATION_DT_S}"))["trace"].arrays()
        volumes.append(a["lung_volume_change_l"])
    t, drift = a["t_s"], volumes[1]
    v = volumes[0] - drift
    fit = t >= RELAXATION_FIT_FROM_S

    def law(t_, v_inf, amp, tau):
        return v_inf * (1.0 - amp * np.exp(-t_ / tau))

    guess = (v[-1], 1.0, r * v[-1] / RELAXATION_STEP_CMH2O)
    (v_inf, amp, tau), _ = curve_fit(law, t[fit], v[fit], p0=guess)
    compliance = v_inf / RELAXATION_STEP_CMH2O
    return {
        "airway_resistance_cmh2o_s_per_l": r,
        "step_cmh2o": RELAXATION_STEP_CMH2O,
        "dt_s": RELAXATION_DT_S,
        "duration_s": duration_s,
        "fit_from_s": RELAXATION_FIT_FROM_S,
        "compliance_l_per_cmh2o": float(compliance),
        "tau_fitted_s": float(tau),
        "tau_rc_s": float(r * compliance),
        "tau_ratio": float(tau / (r * compliance)),
        # tau / C - R: what the chest wall's own dissipation adds to the airway's resistance (the
        # membrane's drag and its soft modes' creep), if the rest of the departure is theirs
        "chest_wall_resistance_implied_cmh2o_s_per_l": float(tau / compliance - r),
        "fit_residual_rel": float(np.max(np.abs(v[fit] - law(t[fit], v_inf, amp, tau))) / abs(v_inf)),
        # the control run's lung volume change at the end (L): the scene's own drift, subtracted
        "control_drift_l": float(drift[-1]),
        "curve": {"t_s": t[:: max(1, len(t) // 400)].tolist(), "volume_l": v[:: max(1, len(t) // 400)].tolist()},
        "fitted": {"v_inf_l": float(v_inf), "amplitude": float(amp)},
    }


def quiet_breathing(scene, duration_s: float) -> dict:
    """Study 3: the scene as it is; its last breath's figures."""
    out = _trace(scene, duration_s, 0.005)
    s, a = out["summary"], out["trace"].arrays()
    period = _breath_period(scene)
    last = a["t_s"] >= duration_s - period - 1e-9
    v, ppl = a["lung_volume_change_l"][last], a["pleural_pressure_cmh2o"][last]
    return {
        "duration_s": duration_s,
        "last_breath_s": period,
        "tidal_volume_l": s["tidal_volume_l"],
        "end_expiratory_pleural_pressure_cmh2o": float(ppl[int(np.argmin(v))]),
        "end_inspiratory_pleural_pressure_cmh2o": float(ppl[int(np.argmax(v))]),
        "transdiaphragmatic_pressure_swing_cmh2o": s["transdiaphragmatic_pressure_swing_cmh2o"],
        "apex_descent_mm": s["apex_descent_mm"],
        "rib_lift_mm": s.get("rib_lift_mm"),
        "work_of_breathing_j_per_l": s["work_of_breathing_j_per_l"],
        "abdomen_share": s.get("abdomen_share"),
        "pulmonary_rib_cage_share": s.get("pulmonary_rib_cage_share"),
        "abdominal_rib_cage_share": s.get("abdominal_rib_cage_share"),
        "mesh_points": s["mesh_points"],
    }


def _breath_period(scene) -> float:
    for f in scene.forces:
        if isinstance(f, MuscleFibres) and isinstance(f.tension_n_per_m, Breathing):
            return f.tension_n_per_m.period_s
    return 4.0


def _peak_tension(scene) -> float:
    for f in scene.forces:
        if isinstance(f, MuscleFibres):
            sched = f.tension_n_per_m
            return float(sched.peak if isinstance(sched, Breathing) else getattr(sched, "value", sched))
    raise SceneError(f"study respiratory: scene {scene.name!r} has no muscle_fibres term for the twitch")


def _twitch_samples(peak: float, contraction_s: float, until_s: float) -> tuple[list, list]:
    """peak (t / T) exp(1 - t / T) sampled every `TWITCH_SAMPLE_S` from 0 up to (not at) until_s."""
    t = np.arange(0.0, until_s, TWITCH_SAMPLE_S)
    return t.tolist(), (peak * (t / contraction_s) * np.exp(1.0 - t / contraction_s)).tolist()


def twitch_tension(peak: float, contraction_s: float = TWITCH_CONTRACTION_S) -> Table:
    """A single twitch's tension: peak (t / T) exp(1 - t / T), which rises from 0 to `peak` at the
    contraction time T and relaxes (the twitch of Fuglevand, Winter & Patla 1993, J Neurophysiol
    70:2470), sampled every `TWITCH_SAMPLE_S` to 8 T (0.7% of the peak left) and 0 after."""
    t, f = _twitch_samples(peak, contraction_s, 8.0 * contraction_s)
    return Table((*t, 8.0 * contraction_s), (*f, 0.0))


def held_tension(peak: float, contraction_s: float = TWITCH_CONTRACTION_S, held_s: float = TWITCH_HELD_S) -> Table:
    """`twitch_tension`'s rise to `peak` at the contraction time, then `peak` held for `held_s`."""
    t, f = _twitch_samples(peak, contraction_s, contraction_s)
    return Table((*t, contraction_s, contraction_s + held_s), (*f, peak, peak))


def _pressures(a: dict) -> dict:
    """A trace's time (s), Pdi's and Pes's changes (cmH2O), every `TWITCH_CURVE_EVERY`-th frame."""
    rows = slice(None, None, TWITCH_CURVE_EVERY)
    pes = a["pleural_pressure_cmh2o"] - a["pleural_pressure_cmh2o"][0]
    return {
        "t_s": a["t_s"][rows].tolist(),
        "pdi_change_cmh2o": a["transdiaphragmatic_pressure_change_cmh2o"][rows].tolist(),
        "pes_change_cmh2o": pes[rows].tolist(),
    }


def _walls(a: dict, k: int) -> dict:
    """The walls' volume changes (L) at row k of a trace, where the scene has them."""
    return {p: float(a[f"{p}_volume_change_l"][k]) for p in ("rib_cage_pulmonary", "rib_cage_abdominal", "abdomen")}


def twitch(scene) -> dict:
    """Study 4: the occluded twitch's dPes / dPdi at the peak of Pdi; and the same contraction
    held (`TWITCH_HELD_S`), its dPes / dPdi at the end: the quasi-static split, which the passive
    compartments' C_ab / (C_ab + C_rc) predicts but for the diaphragm's insertional pull."""
    peak = _peak_tension(scene)
    occluded = _with(scene, tension=twitch_tension(peak), airway_occluded=Constant(1.0))
    a = _trace(occluded, 5.0 * TWITCH_CONTRACTION_S, 0.002)["trace"].arrays()
    pdi = a["transdiaphragmatic_pressure_change_cmh2o"]
    k = int(np.argmax(pdi))
    dpes = float(a["pleural_pressure_cmh2o"][k] - a["pleural_pressure_cmh2o"][0])
    out = {
        "tension_n_per_m": peak,
        "contraction_s": TWITCH_CONTRACTION_S,
        "pdi_peak_s": float(a["t_s"][k]),
        "pdi_change_cmh2o": float(pdi[k]),
        "pes_change_cmh2o": dpes,
        "gastric_pressure_change_cmh2o": float(a["pressure_pa"][k] - a["pressure_pa"][0]) / CMH2O_PA,
        "lung_volume_change_l": float(np.max(np.abs(a["lung_volume_change_l"]))),
        "twitch_pes_over_pdi": abs(dpes) / float(pdi[k]),
        "held_s": TWITCH_HELD_S,
        "curve": {"twitch": _pressures(a)},
    }
    if "rib_cage_pulmonary_volume_change_l" in a:  # how the dome's pull moved the walls, at Pdi's peak
        out["compartment_volume_change_l"] = _walls(a, k)
    held = _with(scene, tension=held_tension(peak), airway_occluded=Constant(1.0))
    try:
        b = _trace(held, TWITCH_CONTRACTION_S + TWITCH_HELD_S, 0.002)["trace"].arrays()
    except RunFailed as exc:  # the twitch's figures stand; the report says why the held one is missing
        out["held_failed"] = " ".join(str(exc).split())
        return out
    held_pdi = float(b["transdiaphragmatic_pressure_change_cmh2o"][-1])
    held_pes = float(b["pleural_pressure_cmh2o"][-1] - b["pleural_pressure_cmh2o"][0])
    out.update(
        held_pdi_change_cmh2o=held_pdi,
        held_pes_change_cmh2o=held_pes,
        held_pes_over_pdi=abs(held_pes) / held_pdi,
        held_lung_volume_change_l=float(np.max(np.abs(b["lung_volume_change_l"]))),
    )
    out["curve"]["held"] = _pressures(b)
    if "rib_cage_pulmonary_volume_change_l" in b:
        out["held_compartment_volume_change_l"] = _walls(b, -1)
    return out


def upper_rib_scene(scene, activation: float):
    """`scene` given the breathing trunk's upper rib pair (`hybrid.demo.UPPER_RIBS`: the pulmonary
    rib cage, sloping down to the front, 0.10-0.14 m high, a motor of 2 N m on each hinge) that
    carries the cavity's wall, its muscles driven by a breathing cycle of peak `activation` (0: the
    diaphragm alone), the cavity's top at `hybrid.demo.UPPER_RIB_WALL_TOP_M`. The pair's stiffness
    and gear are chosen, not sourced."""
    if scene.rigid is None:
        raise SceneError(f"study respiratory: scene {scene.name!r} has no rigid part for an upper rib pair")
    period = _breath_period(scene)
    muscles = Breathing(period_s=period, inspiration_fraction=0.4, peak=activation) if activation else None
    from ..model import compile_scene

    border_z = float(compile_scene(scene).arrays.lung_wall[:, 2].max()) - _lungs_of(scene).wall_height_m
    return with_upper_ribs(scene, muscles, UPPER_RIB_WALL_TOP_M - border_z)


def paradox(scene, at_s: float | None = None) -> dict:
    """Study 5: the mean hinge angle change (mrad) of the lower ribs (the bodies the membrane is
    linked to) and of the upper ribs (those carrying the lungs' wall) at the end of inspiration
    (40% of the breath; or at `at_s` s), the diaphragm alone and with the upper ribs' muscles. A scene whose
    lungs' wall already rides on ribs of its own (`Lungs.wall_bodies`: the fitted trunk's upper
    pair) is examined with those, the diaphragm alone being the scene without its `rigid.ctrl`
    (None with the muscles when it has none); any other is given an upper rib pair
    (`upper_rib_scene`)."""
    from .. import load
    from ..rigid.describe import hinge_qpos

    own = _lungs_of(scene).wall_bodies
    if own is not None:
        upper_pattern = own
        alone = dataclasses.replace(scene, rigid=dataclasses.replace(scene.rigid, ctrl={}))
        cases = {"diaphragm_alone": alone, "with_rib_cage_muscles": scene if scene.rigid.ctrl else None}
    else:
        upper_pattern = "upper_ribs_*"
        cases = {
            label: upper_rib_scene(scene, act)
            for label, act in (("diaphragm_alone", 0.0), ("with_rib_cage_muscles", 1.0))
        }
    out: dict = {}
    period = _breath_period(scene)
    for label, sc in cases.items():
        if sc is None:
            out[label] = None
            continue
        sim = load(sc)
        m, d = sim.mj_model, sim.mj_data
        lower_bodies = {link.body for link in sc.rigid.links}
        upper = hinge_qpos(m, lambda name: fnmatch.fnmatchcase(name, upper_pattern))
        lower = hinge_qpos(m, lambda name: name in lower_bodies and not fnmatch.fnmatchcase(name, upper_pattern))
        q0 = d.qpos.copy()
        sim.step(int(round((0.4 * period if at_s is None else at_s) / sim.model.dt_s)))
        out[label] = {
            "lower_rib_angle_mrad": 1e3 * float(np.mean(d.qpos[lower] - q0[lower])),
            "upper_rib_angle_mrad": 1e3 * float(np.mean(d.qpos[upper] - q0[upper])),
        }
    return out


def study_scene(source="breathing_lungs", *, small: bool = False, level: int | None = None, overrides=()):
    """The scene the study examines: `source` with `overrides` ("KEY=VALUE", as `hybrid run
    --set`) at mesh `level` (default: the scene's; small: 0). Refused (SceneError, one line)
    without lungs or with a bad override."""
    scene = resolve_scene(source, overrides=overrides)
    _lungs_of(scene)
    if small and level is None:
        level = 0
    if level is not None:
        scene = resolve_scene(scene, overrides=(f"mesh.level={level}",))
    return scene


def run(out_dir, source="breathing_lungs", *, small: bool = False, level: int | None = None, overrides=()) -> dict:
    """The study (module docstring) of the scene `source` with `overrides` at mesh `level`
    (`study_scene`); writes DIR/respiratory.json, .md and .png."""
    t0 = time.process_time()
    scene = study_scene(source, small=small, level=level, overrides=overrides)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    period = _breath_period(scene)
    res: dict = {"scene": scene.name, "level": scene.mesh.level, "small": small, "overrides": list(overrides)}
    parts = {
        "passive": lambda: [passive_compliance(scene, p, 2.0) for p in COMPLIANCE_STEPS_CMH2O],
        "relaxation": lambda: relaxation(scene, 15.0 if small else 30.0),
        "quiet_breathing": lambda: quiet_breathing(scene, (2 if small else 3) * period),
        "twitch": lambda: twitch(scene),
        "paradox": lambda: paradox(scene) if scene.rigid is not None else None,
    }
    for key, part in parts.items():  # the JSON holds each part as it ends: a study that fails keeps them
        res[key] = part()
        res["runtime_cpu_s"] = time.process_time() - t0
        write_json(out / "respiratory.json", {**res, "complete": False})
    res["bands"] = _band_rows(res)
    res["complete"] = True
    write_json(out / "respiratory.json", res)
    _write_text(out / "respiratory.md", markdown(res))
    plot(out / "respiratory.png", res)
    return res


def _band_rows(res) -> list[dict]:
    found = dict(res["quiet_breathing"])
    found["respiratory_system_compliance_l_per_cmh2o"] = res["passive"][0]["respiratory_system_compliance_l_per_cmh2o"]
    found["twitch_pes_over_pdi"] = res["twitch"]["twitch_pes_over_pdi"]
    rows = []
    for key, (lo, hi, source) in BANDS.items():
        value = found.get(key)
        ok = None if value is None or not math.isfinite(value) else bool(lo <= value <= hi)
        rows.append({"metric": key, "value": value, "low": lo, "high": hi, "within": ok, "source": source})
    return rows
