"""The respiratory study's report (`hybrid.studies.respiratory`): its markdown page, which the
docs generate from the study's JSON (`hybrid.docgen`), and its figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..outputs import save_figure

__all__ = ["markdown", "plot"]


def markdown(res: dict) -> str:
    """The study's page (DIR/respiratory.md, and the docs' validation section) from its JSON."""

    def num(x, spec=".3g"):
        return "-" if x is None else format(x, spec)

    band = "\n".join(
        f"| {r['metric']} | {num(r['value'])} | {r['low']:g} to {r['high']:g} | "
        f"{'-' if r['within'] is None else ('yes' if r['within'] else 'no')} | {r['source']} |"
        for r in res["bands"]
    )
    passive = "\n".join(
        f"| {p['step_cmh2o']:g} | {p['volume_change_l']:.4f} | {p['respiratory_system_compliance_l_per_cmh2o']:.4f} | "
        f"{p['chest_wall_compliance_l_per_cmh2o']:.4f} | {p['lung_compliance_l_per_cmh2o']:.4f} "
        f"({p['law_lung_compliance_l_per_cmh2o']:g}) |"
        for p in res["passive"]
    )
    comp = "\n".join(
        f"| {p['step_cmh2o']:g} | {p['pleural_pressure_change_cmh2o']:+.3f} | {p['gastric_pressure_change_cmh2o']:+.3f} | "
        f"{1e3 * p['compartment_volume_change_l']['rib_cage_pulmonary']:+.2f} | "
        f"{1e3 * p['compartment_volume_change_l']['rib_cage_abdominal']:+.2f} | "
        f"{1e3 * p['compartment_volume_change_l']['abdomen']:+.2f} | {p['rib_cage_compliance_l_per_cmh2o']:.4f} | "
        f"{p['abdomen_compliance_l_per_cmh2o']:.4f} | {p['twitch_ratio_two_compartments']:.3f} |"
        for p in res["passive"]
        if "rib_cage_compliance_l_per_cmh2o" in p
    )
    compartments = (
        f"""
Its compartments (Konno & Mead): the rib cage's compliance under the pleural pressure's change
(pulmonary and abdominal rib cage), the abdomen's under its own (gastric) pressure's, and the occluded
twitch's dPes / dPdi that two such compartments imply, C_ab / (C_ab + C_rc) (the diaphragm's insertional
and appositional pulls on the ribs left out). Konno & Mead 1968 (J Appl Physiol 24:544) find the abdomen
about as compliant as the rib cage in quiet breathing (somewhat more supine), which makes it about 0.5.

| step (cmH2O) | dPpl | dPga | pulmonary RC (mL) | abdominal RC (mL) | abdomen (mL) | C_rc (L/cmH2O) | C_ab | twitch ratio implied |
| --- | --- | --- | --- | --- | --- | --- | --- | --- |
{comp}
"""
        if comp
        else ""
    )
    r = res["relaxation"]
    tw = res["twitch"]
    par = res["paradox"]
    par_rows = (
        "\n".join(
            f"| {k.replace('_', ' ')} | {v['lower_rib_angle_mrad']:+.3g} | {v['upper_rib_angle_mrad']:+.3g} |"
            for k, v in par.items()
        )
        if par
        else "| (no rigid part) | - | - |"
    )
    return f"""# Respiratory mechanics of scene {res["scene"]} (mesh level {res["level"]})

Made by `hybrid study respiratory{_command_args(res)}`; {res["runtime_cpu_s"]:.0f} s of CPU.
Nothing is fitted: every figure is a prediction of the scene's parameters; the bands are an adult's.

## Against quiet breathing in an adult

| metric | value | band | within | source |
| --- | --- | --- | --- | --- |
{band}

## Passive respiratory system (muscles relaxed, steps of airway-opening pressure)

| step (cmH2O) | volume (L) | C_rs (L/cmH2O) | C_cw | C_L (the law's) |
| --- | --- | --- | --- | --- |
{passive}
{compartments}
## Relaxation after a step: tau = R C

Airway resistance {r["airway_resistance_cmh2o_s_per_l"]:g} cmH2O s/L, step {r["step_cmh2o"]:g} cmH2O, implicit Euler
at {r["dt_s"]:g} s, fitted from {r["fit_from_s"]:g} s: tau {r["tau_fitted_s"]:.4f} s against R C
{r["tau_rc_s"]:.4f} s (ratio {r["tau_ratio"]:.4f}; the fit's largest residual {r["fit_residual_rel"]:.1e} of the volume){_drift(r)}.
The departure is what the chest wall's own dissipation adds to the airway's resistance (the membrane's
drag, and the creep of its soft modes, slow on finer meshes): tau / C - R =
{r["chest_wall_resistance_implied_cmh2o_s_per_l"]:.3g} cmH2O s/L.

## Twitch with the airway occluded

The diaphragm alone, {_twitch_words(tw)}: Pdi {tw["pdi_change_cmh2o"]:+.3g} cmH2O,
Pes {tw["pes_change_cmh2o"]:+.3g} cmH2O, ratio {tw["twitch_pes_over_pdi"]:.3f} (band 0.35-0.55){_implied(res)}.
{_twitch_walls(tw)}{_held(tw)}
## The paradox of a rib cage without its muscles (hinge angles at end inspiration, mrad)

| drive | lower ribs | upper ribs |
| --- | --- | --- |
{par_rows}
"""


def _drift(r: dict) -> str:
    """The control run's drift, subtracted from the step's run (absent from older reports)."""
    if "control_drift_l" not in r:
        return ""
    return f"; the step's run less a control run without it, whose volume drifted {1e3 * r['control_drift_l']:+.3g} mL"


def _command_args(res: dict) -> str:
    """The study's options as the command line gives them (the scene aside)."""
    return (" --small" if res["small"] else "") + "".join(f" --set {o}" for o in res.get("overrides", ()))


def _twitch_words(tw: dict) -> str:
    """The twitch's tension as the report says it (a step held, before 0.23)."""
    if "pdi_peak_s" not in tw:
        return f"at {tw['tension_n_per_m']:g} N/m for {tw['contraction_s']:g} s"
    return (
        f"a twitch of {tw['tension_n_per_m']:g} N/m at its peak, {1e3 * tw['contraction_s']:g} ms after the "
        f"stimulus (Pdi's peak at {1e3 * tw['pdi_peak_s']:.0f} ms)"
    )


def _held(tw: dict) -> str:
    """The same contraction held (absent from reports before 0.24)."""
    if "held_failed" in tw:
        return f"Held at its peak for {tw['held_s']:g} s: the run failed ({tw['held_failed']}).\n"
    if "held_pes_over_pdi" not in tw:
        return ""
    line = (
        f"Held at its peak for {tw['held_s']:g} s (no inertia left): Pdi {tw['held_pdi_change_cmh2o']:+.3g} cmH2O, "
        f"Pes {tw['held_pes_change_cmh2o']:+.3g} cmH2O, ratio {tw['held_pes_over_pdi']:.3f}"
    )
    if "held_compartment_volume_change_l" in tw:
        v = {k: 1e3 * x for k, x in tw["held_compartment_volume_change_l"].items()}
        line += (
            f"; the walls (mL): pulmonary rib cage {v['rib_cage_pulmonary']:+.1f}, abdominal rib cage "
            f"{v['rib_cage_abdominal']:+.1f}, abdomen {v['abdomen']:+.1f}"
        )
    return line + ".\n"


def _twitch_walls(tw: dict) -> str:
    """How the walls moved at Pdi's peak: in a subject the dome descends, the abdomen moves out and
    the gastric pressure rises (the rib cage drawn in by the pleural pressure's fall)."""
    if "compartment_volume_change_l" not in tw:
        return ""
    v = {k: 1e3 * x for k, x in tw["compartment_volume_change_l"].items()}
    return (
        f"At Pdi's peak Pga {tw['gastric_pressure_change_cmh2o']:+.3g} cmH2O; the walls' volume changes "
        f"(mL): pulmonary rib cage {v['rib_cage_pulmonary']:+.1f}, abdominal rib cage "
        f"{v['rib_cage_abdominal']:+.1f}, abdomen {v['abdomen']:+.1f} (their sum the lung volume's change, "
        f"held by the occluded airway); the dome's descent, the last two (Mead & Loring), "
        f"{v['rib_cage_abdominal'] + v['abdomen']:+.1f} mL.\n"
    )


def _implied(res: dict) -> str:
    p = res["passive"][0]
    if "twitch_ratio_two_compartments" not in p:
        return ""
    return f"; the passive compartments above imply {p['twitch_ratio_two_compartments']:.3f}"


def plot(path: Path, res: dict) -> None:
    """The relaxation's volume with its fit, the passive pressure-volume points, and (since 0.24)
    the occluded twitch's and held contraction's pressures over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = res["relaxation"]
    curves = res["twitch"].get("curve")
    fig, axes = plt.subplots(1, 3 if curves else 2, figsize=(15 if curves else 10, 4))
    ax1, ax2 = axes[0], axes[1]
    t = np.asarray(r["curve"]["t_s"])
    ax1.plot(t, 1e3 * np.asarray(r["curve"]["volume_l"]), "k-", label="simulated")
    f = r["fitted"]
    ax1.plot(t, 1e3 * f["v_inf_l"] * (1 - f["amplitude"] * np.exp(-t / r["tau_fitted_s"])), "r--", label="fit")
    ax1.axvline(r["fit_from_s"], color="0.7", lw=0.8)
    ax1.set_xlabel("time (s)")
    ax1.set_ylabel("lung volume change (mL)")
    ax1.set_title(f"relaxation: tau {r['tau_fitted_s']:.3f} s, R C {r['tau_rc_s']:.3f} s")
    ax1.legend()
    p = res["passive"]
    ax2.plot([0] + [q["step_cmh2o"] for q in p], [0] + [q["volume_change_l"] for q in p], "o-", label="P_ao (system)")
    ax2.plot(
        [0] + [q["pleural_pressure_change_cmh2o"] for q in p],
        [0] + [q["volume_change_l"] for q in p],
        "s-",
        label="P_pl (chest wall)",
    )
    ax2.set_xlabel("pressure change (cmH2O)")
    ax2.set_ylabel("lung volume change (L)")
    ax2.set_title("passive pressure-volume, muscles relaxed")
    ax2.legend()
    if curves:
        _plot_twitch(axes[2], res["twitch"], curves)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def _plot_twitch(ax, tw: dict, curves: dict) -> None:
    """Pdi and -Pes over time, the twitch's (solid) and the held contraction's (dashed), with Pdi's
    peak marked where the study reads the twitch's ratio."""
    for name, style in (("twitch", "-"), ("held", "--")):
        if name not in curves:  # the held run failed (its reason in the report)
            continue
        c = curves[name]
        t = 1e3 * np.asarray(c["t_s"])
        ax.plot(t, c["pdi_change_cmh2o"], style, color="k", label=f"Pdi, {name}")
        ax.plot(t, -np.asarray(c["pes_change_cmh2o"]), style, color="tab:blue", label=f"-Pes, {name}")
    ax.axvline(1e3 * tw["pdi_peak_s"], color="0.6", lw=0.8)
    ax.set_xlabel("time after the stimulus (ms)")
    ax.set_ylabel("pressure change (cmH2O)")
    held = f"{tw['held_pes_over_pdi']:.3f} held" if "held_pes_over_pdi" in tw else "held failed"
    ax.set_title(f"occluded: Pes/Pdi {tw['twitch_pes_over_pdi']:.3f} twitch, {held}")
    ax.legend(fontsize="small")
