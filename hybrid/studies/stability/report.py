"""The outputs of the stability study: JSON without NaN, the PNG plots and the
Markdown summary.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ...outputs import save_figure as _save_figure
from ...outputs import write_text as _write_text
from .tables import KV_UNIT, M_UNIT, MODELS, rho_table1

__all__ = ["finite", "write_json", "plots", "markdown"]


def finite(x):
    """JSON-safe: non-finite floats become None (never NaN in our outputs)."""
    if isinstance(x, dict):
        return {str(k): finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    if isinstance(x, np.ndarray):
        return finite(x.tolist())
    return x


def write_json(path: Path, data) -> None:
    _write_text(path, json.dumps(finite(data), indent=2, allow_nan=False))


def plots(out: Path, res: dict) -> list[str]:
    """DIR/<section>.png for each plotted section present in `res`; the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawers = {
        "stability_map": _draw_map,
        "membrane_spectrum": _draw_spectrum,
        "self_excitation": _draw_self_excitation,
    }
    files = []
    for section, draw in drawers.items():
        if res.get(section):
            fig = draw(plt, res[section])
            fig.tight_layout()
            _save_figure(fig, out / f"{section}.png", dpi=110)
            plt.close(fig)
            files.append(f"{section}.png")
    return files


def _draw_map(plt, mp: dict):
    """Outcomes over (h, k) for both models, with the three-point bound |lambda| = 1."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    hs, ks = np.array(mp["h"]), np.array(mp["k"])
    for ax, name in zip(axes, MODELS):
        g = np.array(mp[name]["outcome"])
        ax.pcolormesh(hs, ks, g, cmap="RdYlGn", vmin=-1, vmax=1, shading="nearest")
        hh = np.linspace(0.01, hs.max(), 300)
        kk = np.geomspace(ks.min(), ks.max(), 300)
        th = np.array([[rho_table1(name, h, k, KV_UNIT, M_UNIT) < 1 for h in hh] for k in kk])
        ax.contour(hh, kk, th.astype(float), levels=[0.5], colors="k")
        ax.set_xscale("linear")
        ax.set_yscale("log")
        ax.set_xlabel(f"h (dimensionless, m = {M_UNIT:g}, kv = {KV_UNIT:g})")
        ax.set_title(f"{name}: icosahedron 0.3 l0 (green: equilibrium)\nline: three-point |lambda| = 1")
    axes[0].set_ylabel("k (unified weight)")
    return fig


def _draw_spectrum(plt, ms: dict):
    """The eigenvalues of the membrane's linearized step against the unit circle."""
    fig, ax = plt.subplots(figsize=(5, 5))
    t = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(t), np.sin(t), "k-", lw=0.8)
    ax.plot(ms["eigenvalues_re"], ms["eigenvalues_im"], ".", ms=4)
    ax.set_aspect("equal")
    ax.set_title(f"breathing membrane, one step at h = {ms['dt_s']:g} s\nrho = {ms['spectral_radius_at_dt']:.6f}")
    return fig


def _draw_self_excitation(plt, se: dict):
    """Spectral radius - 1 of the membrane's step against the damping fraction."""
    fig, ax = plt.subplots(figsize=(5.5, 4))
    f = [r["critical_fraction"] for r in se["spectral_radius_by_fraction"]]
    r = [r["spectral_radius"] - 1 for r in se["spectral_radius_by_fraction"]]
    ax.plot(f, r, "o-")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xlabel("damping, fraction of critical")
    ax.set_ylabel("spectral radius - 1 (h = 1 ms)")
    ax.set_title("shape memory self-excitation (breathing membrane)")
    return fig


def _fmt(x, spec=".3g"):
    return "-" if x is None else format(x, spec)


def markdown(res: dict) -> str:
    L = ["# Stability study (paper 6.1)", ""]
    L += [
        f"Table 1: max |eigenvalue(Jacobian of our step) - closed form| = {res['table1_max_abs_error']:.2e} "
        f"over {len(res['table1']['rows'])} (model, h, k, kv, m) cases.",
        "",
    ]
    t2 = res["table2"]
    L += [
        f"Table 2 (three-point system, m = {t2['m']:g}, kv = {t2['kv']:g}): largest stable h by k",
        "",
        "| k | mass-spring h_max | shape memory h_max |",
        "|---|---|---|",
    ]
    for r in t2["h_max_by_k"]:
        L.append(
            f"| {r['k']:g} | {r['mass_spring']['h_max_eigenvalues']:.4f} | "
            f"{r['shape_memory']['h_max_eigenvalues']:.4f} |"
        )
    L += ["", "largest stable k by h", "", "| h | mass-spring k_max | shape memory k_max |", "|---|---|---|"]
    for r in t2["k_max_by_h"]:
        L.append(
            f"| {r['h']:g} | {r['mass_spring']['k_max_eigenvalues']:.4f} | "
            f"{r['shape_memory']['k_max_eigenvalues']:.4f} |"
        )
    L += ["", "```", t2["notes"], "```", ""]
    L += [
        "Table 3: icosahedron, largest h reaching equilibrium (ours / paper) and iterations at h = 1",
        "",
        "| model | perturbation | h_max (min over seeds) | median | paper | iterations (h = 1) | "
        "shape error at equilibrium (l0) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in res["table3"]:
        L.append(
            f"| {r['model']} | {r['perturbation']} l0 | {_fmt(r['h_max'])} | "
            f"{_fmt(r['h_max_median_over_seeds'])} | {r['paper_h_max']} | "
            f"{_fmt(r['iterations'], 'd') if r['iterations'] is not None else '-'} | "
            f"{_fmt(r['shape_error_l0_at_h1_max'], '.2g')} |"
        )
    L += ["", "Setup: " + json.dumps(res["table3_setup"]), ""]
    ms = res.get("membrane_spectrum")
    if ms:
        L += [
            "Breathing membrane (80 points, symplectic Euler):",
            "",
            f"- per-point estimate (model.dt_stable_s): {ms['h_max_per_point_estimate']:.4g} s",
            f"- linearized step (spectral radius <= 1): {_fmt(ms['h_max_linearized'], '.4g')} s",
            f"- observed (small perturbation, 1 s): {_fmt(ms['h_max_observed'], '.4g')} s",
            f"- observed (one breath with muscles, membrane only): "
            f"{_fmt(ms['h_max_observed_breath_membrane_only'], '.4g')} s",
            f"- observed (one breath, coupled to the ribs): {_fmt(ms['h_max_observed_breath_coupled'], '.4g')} s",
            "",
        ]
    se = res.get("self_excitation")
    if se:
        L += [
            f"Self-excitation: the undriven membrane is stable for critical_fraction >= "
            f"{se['critical_fraction_min_linearized']:.4g} (linearized) / "
            f"{se['critical_fraction_min_observed']:.4g} (runs).",
            "",
        ]
    L += [f"Run time: {res['runtime_s']:.1f} s; plots: {', '.join(res['plots'])}"]
    return "\n".join(L) + "\n"
