"""The compiled-code cache: a folder per version of the kernel sources (an edit
elsewhere keeps it), writes locked, entries safe to load in any order."""

import shutil
import subprocess
import sys
from pathlib import Path


def test_cache_folder_follows_numba_cache_dir_and_saves_are_locked(tmp_path):
    code = ("import hybrid.kernel as k, numba.core.caching as c; "
            "print(k.CACHE_DIR); print(getattr(c.IndexDataCacheFile.save, '_hybrid_locked', False))")
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True).stdout.split()
    assert out[0].startswith(str(tmp_path / "numba-"))
    assert out[1] == "True"


def _package_copy(tmp_path) -> Path:
    import hybrid.kernel as k

    copy = tmp_path / "hybrid"
    shutil.copytree(Path(k.__file__).parent, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def _edit(path: Path) -> None:
    path.write_text(path.read_text() + "\n# an edit\n")


def test_the_kernel_sources_are_the_compiling_modules_and_what_they_import(tmp_path):
    import hybrid.kernel as k

    package = _package_copy(tmp_path)
    names = {p.relative_to(package).as_posix() for p in k.kernel_sources(package)}
    assert {"kernel.py", "terms/shape_memory.py", "terms/volume.py", "step.py", "coupling.py", "schedule.py"} <= names
    assert {"errors.py", "scene.py"} <= names  # imported by kernels: their constants compile in
    assert not names & {"render.py", "cli.py", "run.py", "sweep.py", "__init__.py", "studies/cli.py"}


def test_cache_folder_follows_the_kernel_sources_only(tmp_path):
    import hybrid.kernel as k

    package = _package_copy(tmp_path)
    before = k._cache_dir(package)
    _edit(package / "render.py")  # an observer: nothing compiled changes
    _edit(package / "studies" / "cli.py")
    (package / "notes.py").write_text("import numpy\n")
    assert k._cache_dir(package) == before
    _edit(package / "terms" / "muscle.py")  # a kernel module
    after_kernel = k._cache_dir(package)
    assert after_kernel != before
    _edit(package / "scene.py")  # imported by kernel modules
    assert k._cache_dir(package) != after_kernel
    # a new module that compiles counts without being listed anywhere, and so do its imports
    (package / "notes.py").write_text("from .kernel import kernel\nfrom . import render\n")
    with_new = k._cache_dir(package)
    assert with_new != after_kernel
    _edit(package / "render.py")
    assert k._cache_dir(package) != with_new


def test_a_kernel_compiled_beside_cached_parallel_twins_loads_in_a_new_process(tmp_path):
    """numba issue 8578: the breathing trunk caches the parallel twins; a later process
    compiles the membrane-only step beside them (loaded from the cache); a third process
    that loads that step first crashed (a null call, exit -11) before hybrid started
    numba's threading layer at import."""
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    membrane = "import hybrid; from hybrid.demo import membrane_demo; hybrid.load(membrane_demo()).step(2)"
    for code in ("import hybrid; hybrid.load('breathing').step(2)", membrane, membrane):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert done.returncode == 0, (code, done.returncode, done.stderr[-2000:])
