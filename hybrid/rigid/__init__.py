"""The rigid part at model time: MuJoCo ribs and spine, composed with `mujoco.MjSpec`.

With `hybrid.coupling` (MuJoCo at step time: the coupled loop) this package is the
only place of `hybrid` that imports mujoco; the rest of the package imports it
lazily, so that a membrane-only scene never loads MuJoCo. By concern:

- `mjcf`: MJCF files and package models ("myo_sim:myotorso") loaded into an MjSpec,
  compiling with readable errors, MuJoCo's warnings sent to the log;
- `controls`: what a scene changes in its model (`rigid.fix`, `weld`, `hold`, `lock`,
  `keyframe`, `ctrl`, `integrator`), each name checked against the model;
- `ribs`: articulated rib pairs added to a thoracic body (`rigid.ribs`);
- `compose`: what hybrid adds to a spec (ribs, attachment sites, link masses), the
  scene's rigid part (`build_rigid`) and the free body of the rigid study;
- `system`: the compiled system driven by point forces (`RigidSystem`,
  `CoupledRigid`) and the compiled site kernels the coupled step shares;
- `replay`: recorded wrenches (and controls) through MuJoCo alone;
- `describe`: what a compiled model holds, as plain data (`hybrid inspect`);
- `draw`: MuJoCo's viewer for `hybrid view`;
- `references`: MuJoCo alone, what the benchmark times our step against.
"""

from .compose import add_sites, attach_points, build_rigid, free_body_spec
from .draw import draw_capsules, empty_world, launch_viewer, show_geom_groups
from .mjcf import BUILTIN_MJCF, PACKAGE_MJCF, TRUNK_XML, compile_spec, load_rigid_spec, load_spec, resolve_mjcf
from .references import BareStepper, FlexSphere
from .replay import replay_states, replay_wrenches
from .system import (
    STATE_SPEC,
    CoupledRigid,
    RigidSystem,
    get_state,
    mj_step_ctypes,
    mj_wall_addresses,
    point_wrench_kernel,
    site_vel_kernel,
)

__all__ = [
    "TRUNK_XML",
    "BUILTIN_MJCF",
    "PACKAGE_MJCF",
    "STATE_SPEC",
    "load_spec",
    "compile_spec",
    "resolve_mjcf",
    "load_rigid_spec",
    "add_sites",
    "attach_points",
    "build_rigid",
    "free_body_spec",
    "RigidSystem",
    "CoupledRigid",
    "get_state",
    "replay_wrenches",
    "replay_states",
    "point_wrench_kernel",
    "site_vel_kernel",
    "mj_step_ctypes",
    "mj_wall_addresses",
    "empty_world",
    "launch_viewer",
    "draw_capsules",
    "show_geom_groups",
    "BareStepper",
    "FlexSphere",
]
