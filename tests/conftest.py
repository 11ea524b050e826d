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
