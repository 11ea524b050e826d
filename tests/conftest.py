"""Fixtures shared by the test files: the packaged breathing scene, the closed test
surfaces and a Dask cluster."""

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


@pytest.fixture(scope="session")
def dask_cluster():
    """A local Dask cluster of two worker processes, one thread each."""
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
)


def pytest_collection_modifyitems(config, items):
    for item in items:
        path = item.path.relative_to(config.rootpath / "tests").as_posix()
        if any(path.startswith(s) if s.endswith("/") else f"{path}::{item.name}".startswith(s) for s in SLOW):
            item.add_marker(pytest.mark.slow)
