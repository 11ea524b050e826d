"""The compiled-code cache: a folder per version of hybrid's sources, writes locked,
entries safe to load in any order."""

import subprocess
import sys


def test_cache_folder_follows_numba_cache_dir_and_saves_are_locked(tmp_path):
    code = ("import hybrid.kernel as k, numba.core.caching as c; "
            "print(k.CACHE_DIR); print(getattr(c.IndexDataCacheFile.save, '_hybrid_locked', False))")
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True).stdout.split()
    assert out[0].startswith(str(tmp_path / "numba-"))
    assert out[1] == "True"


def test_cache_folder_changes_with_the_sources(tmp_path, monkeypatch):
    import hybrid.kernel as k

    before = k._cache_dir()
    real = type(k.Path(k.__file__)).read_bytes

    def edited(self):  # as if one source file had changed
        data = real(self)
        return data + b"#" if self.name == "step.py" else data

    monkeypatch.setattr(type(k.Path(k.__file__)), "read_bytes", edited)
    assert k._cache_dir() != before


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
