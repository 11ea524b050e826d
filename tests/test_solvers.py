"""The membrane's solvers as objects (`hybrid.solvers`): a solver passed to `Simulation` steps
exactly as the scene key of its name would, owns its work arrays, and bad ones are refused."""

import dataclasses

import numpy as np
import pytest

import hybrid
from hybrid import ExplicitEuler, ImplicitEuler, Simulation, SymplecticEuler, compile_scene, load_scene
from hybrid.errors import ArgumentError
from hybrid.implicit import Info
from hybrid.integrators import NAMES
from hybrid.solvers import SOLVERS, solver_of


def _run(sim: Simulation, n: int) -> dict:
    sim.step(n)
    out = {"pos": sim.vert_pos.copy(), "vel": sim.vert_vel.copy(), "t": sim.time, "p": sim.pressure}
    if sim.rigid is not None:
        out["qpos"] = sim.mj_data.qpos.copy()
        out["qvel"] = sim.mj_data.qvel.copy()
    return out


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:  # the same compiled code on the same numbers: equal to the bit
        assert np.array_equal(a[k], b[k]), k


def test_every_integrator_of_the_registry_has_its_solver():
    assert tuple(SOLVERS) == NAMES
    for name, cls in SOLVERS.items():
        assert cls().name == name
        assert cls().implicit == (name == "implicit_euler")


@pytest.mark.parametrize(
    "key, solver",
    [("implicit_euler", ImplicitEuler(tol=1e-7, max_iter=40)), ("symplectic_euler", SymplecticEuler())],
    ids=["implicit", "symplectic"],
)
def test_a_solver_passed_to_the_coupled_simulation_steps_as_its_scene_key(key, solver):
    """The breathing trunk (membrane and MuJoCo) at one step: the scene compiled with
    `integrator = key` against the scene compiled with the other integrator and given `solver`."""
    dt = ["dt_s=2e-4"]
    other = "symplectic_euler" if key == "implicit_euler" else "implicit_euler"
    as_key = load_scene("breathing", overrides=[f"integrator={key}", "implicit_tol=1e-7", "implicit_max_iter=40", *dt])
    given = Simulation(compile_scene(load_scene("breathing", overrides=[f"integrator={other}", *dt])), solver=solver)
    assert given.solver == solver
    assert given.model.scene.integrator == key
    _same(_run(Simulation(compile_scene(as_key)), 60), _run(given, 60))


def test_a_solver_passed_to_a_membrane_only_simulation_steps_as_its_scene_key():
    scene = load_scene("membrane_demo")
    explicit = dataclasses.replace(scene, integrator="explicit_euler")
    sim = hybrid.load("membrane_demo", solver=ExplicitEuler())
    assert sim.rigid is None and sim.solver == ExplicitEuler()
    _same(_run(Simulation(compile_scene(explicit)), 200), _run(sim, 200))


def test_the_simulation_says_which_solver_runs_and_only_an_implicit_one_fills_its_work_arrays():
    model = compile_scene(load_scene("breathing", overrides=["integrator=implicit_euler", "implicit_tol=1e-5"]))
    own = Simulation(model)
    assert own.solver == ImplicitEuler(tol=1e-5, max_iter=50) == solver_of(model)
    assert own.solver_work.dv.shape == (model.nvert, 3)
    sym = Simulation(model, solver=SymplecticEuler())
    assert sym.solver == SymplecticEuler() and sym.solver_work.dv.size == 0  # empty, of the same types
    # the model steps with it: the step kept, its stability bound symplectic Euler's (finite)
    assert sym.model.dt_s == model.dt_s and np.isfinite(sym.model.dt_stable_s) and model.dt_stable_s == np.inf
    assert sym.model.arrays.integrator == SymplecticEuler().model_for(model).arrays.integrator
    tight = Simulation(model, solver=ImplicitEuler(tol=1e-9, max_iter=70))
    assert (tight.model.arrays.implicit_tol, tight.model.arrays.implicit_max_iter) == (1e-9, 70)
    own.step(20)
    tight.step(20)  # the solver's tolerance reaches its solve: more Newton iterations for less residual
    newton = [s.solver_work.info[Info.NEWTON_TOTAL] for s in (own, tight)]
    assert 0 < newton[0] < newton[1]


def test_bad_solvers_are_refused_in_one_line_naming_them():
    with pytest.raises(ArgumentError, match=r"^ImplicitEuler\.tol: expected .* received -1$"):
        ImplicitEuler(tol=-1)
    with pytest.raises(ArgumentError, match=r"^ImplicitEuler\.max_iter: expected .* received 2\.5$"):
        ImplicitEuler(max_iter=2.5)
    model = compile_scene(load_scene("membrane_demo"))
    with pytest.raises(ArgumentError, match=r"^solver: expected a hybrid solver .* received str 'implicit'$"):
        Simulation(model, solver="implicit")
    # the paper's forces derive from no energy: no Hessian for Newton's method
    with pytest.raises(ArgumentError, match=r"^solver: ImplicitEuler\(.*\) needs formulation 'continuum'.*'paper'"):
        Simulation(model, solver=ImplicitEuler())


@pytest.mark.parametrize("solver", [SymplecticEuler(), ImplicitEuler()], ids=["symplectic", "implicit"])
def test_a_membrane_scene_and_a_coupled_one_share_the_compiled_loop(solver):
    # the compiled loop's argument types (readonly or writable arrays among them) are its
    # signature: a scene whose types differ compiles the whole loop again (implicit Euler's: 35-80 s
    # on 2 cores). The sliding points of a coupled scene were a read-only array, a membrane's a
    # writable one: two implicit builds, both compiled by the suite
    from numba import typeof

    from hybrid.simulation import _MEMBRANE_ONLY

    scene = load_scene("breathing", overrides=["mesh.level=0"])
    alone = Simulation(compile_scene(dataclasses.replace(scene, rigid=None)), solver=solver)
    coupled = Simulation(compile_scene(scene), solver=solver)
    assert alone.rigid is None and coupled.rigid is not None  # the premise
    for part in ("state", "work", "solver_work"):
        assert typeof(getattr(alone, part)) == typeof(getattr(coupled, part)), part
    assert typeof(alone.model.arrays) == typeof(coupled.model.arrays)
    assert typeof(alone.control.arrays) == typeof(coupled.control.arrays)
    assert typeof(_MEMBRANE_ONLY) == typeof(coupled.rigid.pack(1))


def test_every_solver_steps_through_one_compiled_loop_and_implicit_euler_s_kernels_take_its_types():
    # implicit Euler's solve is compiled apart and called at its address (`hybrid.calls.call_at`):
    # the loop's argument types are the same whichever solver steps (one build, whose compile an
    # implicit scene after a symplectic one skips), and the solve's kernels were compiled for exactly
    # the types the loop passes them (another type there would be read wrongly, not refused)
    from numba import typeof

    from hybrid.implicit import implicit_start_forces, implicit_step

    model = compile_scene(load_scene("breathing", overrides=["mesh.level=0"]))
    sims = {name: Simulation(model, solver=cls()) for name, cls in SOLVERS.items()}
    types = {
        name: tuple(typeof(getattr(sim, p)) for p in ("state", "work", "solver_work")) for name, sim in sims.items()
    }
    assert len(set(types.values())) == 1, types
    imp = sims["implicit_euler"]
    arrays = typeof(imp.model.arrays)
    state, work, solver_work = types["implicit_euler"]
    value = typeof(imp.control.arrays.value)
    assert (
        arrays,
        state,
        value,
        typeof(np.int64(0)),
        solver_work,
        typeof(imp.work.vert_acc),
    ) in implicit_step.overloads
    start = (arrays, value, typeof(imp.state.vert_pos), typeof(imp.state.vert_vel), typeof(imp.state.lung))
    assert (*start, solver_work, typeof(imp.work.vert_force)) in implicit_start_forces.overloads
    assert np.all(imp.work.calls[:2] != 0) and np.all(sims["symplectic_euler"].work.calls == 0)
    from hybrid.loop import run_steps

    sims["symplectic_euler"].step(2)
    loops = set(run_steps.signatures)
    imp.step(2)  # implicit Euler after symplectic Euler: the same loop, no build of its own
    assert set(run_steps.signatures) == loops and imp.steps_done == 2


def test_a_simulation_sent_to_another_process_steps_as_it_would_have_here(tmp_path):
    # its step calls kernels at addresses (`hybrid.step_work.StepWork.calls`), which are the process's
    # own: unpickled elsewhere it must take that process's (a stale address would crash the step)
    import pickle
    import subprocess
    import sys

    from hybrid import Masses, Membrane, RestingTension, Scene
    from hybrid.mesh import irregular_sphere

    scene = Scene(
        mesh=irregular_sphere(120, 0.05, seed=3),
        masses=Masses(total_kg=0.2),
        integrator="implicit_euler",
        dt_s=2e-3,
        forces=(Membrane(400.0, damping_time_s=0.01), RestingTension(tension_n_per_m=5.0)),
    )
    sim = Simulation(compile_scene(scene))
    sim.state.vert_pos[:] *= 1.01  # out of rest: something to solve
    (tmp_path / "sim.pickle").write_bytes(pickle.dumps(sim))
    code = (
        "import pickle, sys, numpy as np\n"
        "sim = pickle.loads(open(sys.argv[1], 'rb').read())\n"
        "sim.step(5)\n"
        "np.save(sys.argv[2], sim.vert_pos)\n"
    )
    out = tmp_path / "pos.npy"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "sim.pickle"), str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert np.all(sim.work.calls[:2] != 0) and sim.work.force_calls.shape[0] == 1
    sim.step(5)
    assert np.array_equal(np.load(out), sim.vert_pos)
