"""The run's figure drawn from its series (`hybrid.outputs.figure_series`): the time
series, a panel each for what the scene has, and with lungs a Campbell and a
Konno-Mead diagram (docs/outputs.md).

This module imports numpy and matplotlib only, so that it also runs as a process of its
own (`python run_figure.py`): `hybrid run` starts it first thing, it imports matplotlib
(about a third of a short warm run) while the run imports, checks and steps, and then
turns the series it reads from its standard input (a pickle) into PNG bytes on its
standard output. The process writes no file: `hybrid.outputs.plot_trace` writes what it
returns.
"""

from __future__ import annotations

import io
import os
import pickle
import signal
import subprocess
import sys

import numpy as np

__all__ = ["PANELS", "LUNG_PRESSURES", "draw", "png_bytes", "FigureProcess"]

# the panels a plot may have, in order: (series, label, log scale); `muscle_n_per_m`'s
# label is the trace's own (`Trace.about["muscle"]`: a stiffness or a fibre tension)
PANELS = (
    ("rib_lift_mm", "rib lift (mm)", False),
    ("apex_descent_mm", "apex descent (mm)", False),
    ("volume_rel_error", "volume error |V - V0| / V0", True),
    ("volume_rel_change", "volume change |V - V0| / V0", False),
    ("pressure_pa", "pressure (Pa)", False),
    ("muscle_n_per_m", "muscle (N/m)", False),
    ("lung_volume_change_l", "lung volume\nabove rest (L)", False),
    ("flow_l_per_s", "flow in (L/s)", False),
    ("pleural_pressure_cmh2o", "pleural pressure,\nPoes (cmH2O)", False),
)
# the lungs' pressures that are 0 at rest, one panel (cmH2O): (series, legend)
LUNG_PRESSURES = (
    ("alveolar_pressure_cmh2o", "alveolar"),
    ("transdiaphragmatic_pressure_change_cmh2o", "Pdi - Pdi(rest)"),
)


def draw(series: dict, *, title: str = ""):
    """The figure (a matplotlib `Figure` of its own, outside pyplot's, whose import costs
    a run 0.1 s of CPU more: nothing to close, drawn by Agg) of `series`: "t_s" and each
    panel's series (`hybrid.outputs.figure_series`), "panels" ((series, label, log) in
    order), "about" and "diagrams" (the Campbell and Konno-Mead series, or None)."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    a, panels, diagrams = series, series["panels"], series["diagrams"]
    konno = diagrams is not None and np.isfinite(diagrams["abdomen_volume_change_l"]).any()
    # fixed margins: tight_layout took half a second of every run
    below = 3.6 if diagrams is not None else 0.0  # the diagrams' row (inches)
    height = 1.2 + 1.6 * len(panels) + below
    fig = Figure(figsize=(7, height))
    grid = fig.add_gridspec(
        len(panels), 1, left=0.13, right=0.97, top=1 - 0.45 / height, bottom=(0.55 + below) / height, hspace=0.15
    )
    axes: list = []
    for i, (key, label, log) in enumerate(panels):
        ax = fig.add_subplot(grid[i, 0], sharex=axes[0] if axes else None)
        axes.append(ax)
        if isinstance(key, tuple):  # several series, one unit
            for name, legend in key:
                ax.plot(a["t_s"], a[name], label=legend)
            ax.legend(fontsize=7, loc="best", ncol=len(key))
        elif log:
            ax.semilogy(a["t_s"], np.maximum(a[key], 1e-17))
            # labels at the decades only: within a decade matplotlib labels the minor ticks,
            # "1.08 x 10^-15" wide, over the panel's own label
            ax.yaxis.set_minor_formatter(NullFormatter())
        else:
            ax.plot(a["t_s"], a[key])
        ax.set_ylabel(label, fontsize=8)
        ax.grid(alpha=0.3)
        if i < len(panels) - 1:
            ax.tick_params(labelbottom=False)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title)
    if diagrams is not None:
        row = fig.add_gridspec(1, 2, left=0.13, right=0.97, top=(below - 0.5) / height, bottom=0.5 / height, wspace=0.4)
        ax = fig.add_subplot(row[0, 0])
        _campbell(ax, diagrams, series["about"])
        ax.grid(alpha=0.3)
        if konno:
            ax = fig.add_subplot(row[0, 1])
            _konno_mead(ax, diagrams)
            ax.grid(alpha=0.3)
    return fig


def png_bytes(series: dict, *, title: str = "") -> bytes:
    """`draw(series, title)` as PNG (100 dpi)."""
    buf = io.BytesIO()
    draw(series, title=title).savefig(buf, dpi=100, format="png")
    return buf.getvalue()


def _campbell(ax, d: dict, about: dict) -> None:
    """Pleural pressure against lung volume, with the lungs' static recoil line (no
    flow, airway open): the loop's width off the line is the airway's resistance."""
    vol, ppl = d["lung_volume_change_l"], d["pleural_pressure_cmh2o"]
    ax.plot(ppl, vol, lw=1)
    e, recoil = about["lung_elastance_cmh2o_per_l"], about["resting_recoil_cmh2o"]
    span = np.array([min(0.0, np.nanmin(vol)), max(0.0, np.nanmax(vol))])
    ax.plot(-recoil - e * span, span, "k--", lw=0.8, label=f"static recoil, E = {e:.3g} cmH2O/L")
    ax.set_xlabel("pleural pressure, Poes (cmH2O)", fontsize=8)
    ax.set_ylabel("lung volume above rest (L)", fontsize=8)
    ax.set_title("Campbell diagram", fontsize=9)
    ax.legend(fontsize=7, loc="best")


def _konno_mead(ax, d: dict) -> None:
    """Rib cage against abdominal displacement (L), the lung volume change's parts: the
    abdomen's wall, and the rib cage's two (the cavity's wall and the abdominal rib cage);
    isovolume lines at 45 degrees."""
    vol = d["lung_volume_change_l"]
    abdomen = d["abdomen_volume_change_l"]
    rib = d["rib_cage_pulmonary_volume_change_l"] + d["rib_cage_abdominal_volume_change_l"]
    ax.plot(abdomen, rib, lw=1)
    top = float(np.nanmax(np.abs(np.concatenate([abdomen, rib, vol]))))
    for level in np.linspace(0.0, float(np.nanmax(vol)), 3)[1:]:
        ax.plot([level - top, level + top], [top, -top], color="0.7", lw=0.6)
    ax.set_xlim(min(0.0, np.nanmin(abdomen)) - 0.1 * top, max(0.0, np.nanmax(abdomen)) + 0.1 * top)
    ax.set_ylim(min(0.0, np.nanmin(rib)) - 0.1 * top, max(0.0, np.nanmax(rib)) + 0.1 * top)
    ax.set_xlabel("abdomen (L)", fontsize=8)
    ax.set_ylabel("rib cage: pulmonary + abdominal (L)", fontsize=8)
    ax.set_title("Konno-Mead diagram", fontsize=9)


class FigureProcess:
    """This module run as a process of its own, started at once: `png(series, title)`
    hands it the series and returns its PNG, or None when it failed (the caller then
    draws in its own process, where an error says what it is); `close()` ends it when
    no figure is drawn. A context manager: the process never outlives it."""

    #: s: the longest wait for the process's figure (a figure takes it well under a second)
    TIMEOUT_S = 120.0

    def __init__(self) -> None:
        # -P: the module's own folder is not put on the import path (its neighbours' names)
        self._proc: subprocess.Popen | None = subprocess.Popen(
            [sys.executable, "-P", __file__],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )

    def png(self, series: dict, title: str = "") -> bytes | None:
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        try:
            out, _ = proc.communicate(pickle.dumps((series, title)), timeout=self.TIMEOUT_S)
        except (OSError, subprocess.SubprocessError):
            _end(proc)
            return None
        return out if proc.returncode == 0 and out.startswith(b"\x89PNG") else None

    def close(self) -> None:
        proc, self._proc = self._proc, None
        if proc is not None:
            _end(proc)

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _end(proc: subprocess.Popen) -> None:
    proc.kill()
    proc.wait()
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            pipe.close()


def _serve() -> int:
    """The drawing process: matplotlib first, then one (series, title) pickle from the
    standard input, its PNG to the standard output. A pipe closed before the pickle (the
    run was refused, or stopped) ends it quietly. Ctrl-C reaches the run's whole process
    group: ignored here, the run it stops still has its figure drawn (the run ends this
    process in any case)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import matplotlib.figure  # noqa: F401  (the import this process exists to do early)
    from matplotlib.backends import backend_agg  # noqa: F401

    try:
        series, title = pickle.load(sys.stdin.buffer)
    except EOFError:
        return 0
    sys.stdout.buffer.write(png_bytes(series, title=title))
    sys.stdout.buffer.flush()
    # the run waits for this process's end: matplotlib's teardown is of no use to it
    os._exit(0)


if __name__ == "__main__":
    sys.exit(_serve())
