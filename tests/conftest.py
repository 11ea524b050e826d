"""Fixtures shared by the test files: the packaged breathing scene, the closed test
surfaces and a Dask cluster."""

import os

# Threads of the multi-core build that wait for work sleep rather than spin (GNU OpenMP's
# setting; numba's threading layer is OpenMP here), in this process and the ones it starts. Set before numba
# starts its threads (hybrid.kernel, at import). The suite runs two workers on two cores,
# so a parallel kernel always shares its cores: spinning waiters then take the CPU their
# sibling thread needs. Measured beside one busy process, the 10,242-point volume test,
# the implicit builds' and the membrane builds' agreement: 31.9 s -> 10.3 s of CPU,
# 71 s -> 21 s. The builds' results do not depend on it (their sums are in a fixed order).
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import pytest
from helpers import CLOSED

from hybrid.scenefile import builtin_scene, load_scene


@pytest.fixture(scope="session")
def breathing():
    """The paper's breathing trunk (models/scenes/breathing_paper.toml), as a Scene."""
    return load_scene(builtin_scene("breathing_paper"))


@pytest.fixture(params=list(CLOSED), ids=list(CLOSED))
def closed_mesh(request):
    return CLOSED[request.param]((0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def dask_cluster():
    """A local Dask cluster of two worker processes, one thread each, for the tests of one
    module: an idle cluster's heartbeats take about 7 s of CPU a minute (its two workers
    and its scheduler), which a session-long one spent until the suite ended."""
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        yield cluster


#: the slow tier (test files relative to tests/, or single tests "file::name"), marked
#: `slow` here so that `python -m pytest -m "not slow"` is the quick loop of one who edits a
#: module; chosen from one full run's --durations (they compile many kernel sets, run the
#: studies, long scenes, the scripts or other processes). The full run takes them all.
SLOW = (
    "studies/",  # every study, each on its grid of meshes and steps
    "test_breathing_levels.py",  # the breathing scene at mesh levels up to 5
    "test_breathing_continuum.py",
    "test_implicit_coupled.py",  # implicit Euler on the coupled breathing scene
    "test_run_first.py",  # a first run into an empty compile cache, in its own process
    "test_scripts.py",  # each script in its own process
    "test_sweep.py",  # process pools and a Dask cluster
    "test_render.py",  # renders, the MP4 and the viewer on a virtual display
    "test_bench.py",
    "rigid/test_myotorso.py",  # MyoSuite's torso: 210 muscles
    # the slowest of the rest (a quick-tier run's --durations under a load of 12 on 2 cores: 24-183 s each)
    "terms/test_volume.py::test_volume_exact_every_step_icosphere_10242",
    "test_kernel.py::test_a_kernel_compiled_beside_cached_parallel_twins_loads_in_a_new_process",
    "test_architecture.py::test_adding_a_term_takes_the_two_edits_the_architecture_page_shows",
    "test_implicit_matrix.py::test_the_assembled_matrix_is_the_same_compiled_or_loaded_from_the_cache",
    "test_inputs_volume.py::test_projected_step_keeps_the_volume_of_a_small_flat_body_far_away",
    "test_cli.py::test_bench_quick_writes_json",
    "test_runs_safe.py::test_a_second_run_into_a_busy_folder_is_refused_and_sigterm_finishes_the_first",
    "test_runs_safe.py::test_the_runners_memory_does_not_grow_with_the_runs_length",
    "test_body_metrics.py::test_the_body_metrics_converge_under_refinement",  # a breath at four levels
)


def pytest_collection_modifyitems(config, items):
    for item in items:
        path = item.path.relative_to(config.rootpath / "tests").as_posix()
        if any(path.startswith(s) if s.endswith("/") else f"{path}::{item.name}".startswith(s) for s in SLOW):
            item.add_marker(pytest.mark.slow)
