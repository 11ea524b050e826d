"""What a step advances and a checkpoint must hold: `State`.

`Simulation.get_state()` copies it out and `Simulation.set_state(state)` puts it back:
a run split in two at any step through a saved `State` is the run in one piece, bit for
bit (`tests/test_state.py`), with every integrator, with and without MuJoCo. The
solvers' scratch (force buffers, projection and Newton work arrays) is not state: each
step rewrites it before reading it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["State"]


@dataclass(frozen=True, eq=False)
class State:
    """A run's state after `steps_done` steps (all arrays are copies).

    vert_pos (nvert, 3) m, vert_vel (nvert, 3) m/s: the membrane's points;
    scal (8,): time s, pressure Pa and multiplier of the last volume projection, and
    the last step's readouts (`hybrid.step.Scal`);
    vert_grad (nvert, 3) m^2: the last projection's volume gradient (with a rigid part
    the next step sends its pressure force p grad_i V to the ribs);
    term_calls (nterm,): how many times each term's kernel ran;
    lung (`hybrid.terms.lungs.NLUNG`,): the lungs' compartment at the last step's start
    (the next frame's flow is the volume's change since); lung_wall_pos (nwall, 3) m and
    lung_wall_vel (nwall, 3) m/s: the cavity's wall, carried by the rigid bodies;
    implicit_dv (nvert, 3) m/s and implicit_info (`hybrid.implicit.Info`): implicit
    Euler's warm start, carried pressure and run averages (None for other integrators);
    mj_state: MuJoCo's integration state (`mjSTATE_INTEGRATION`: time, qpos, qvel, act,
    warm start, ctrl, applied forces), None without a rigid part.
    """

    steps_done: int
    vert_pos: np.ndarray
    vert_vel: np.ndarray
    scal: np.ndarray
    vert_grad: np.ndarray
    term_calls: np.ndarray
    lung: np.ndarray | None = None
    lung_wall_pos: np.ndarray | None = None
    lung_wall_vel: np.ndarray | None = None
    implicit_dv: np.ndarray | None = None
    implicit_info: np.ndarray | None = None
    mj_state: np.ndarray | None = field(default=None)

    @property
    def time_s(self) -> float:
        """Simulated time (s)."""
        return float(self.scal[0])
