"""The compiled-code cache: a folder per version of hybrid's sources, writes locked."""

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
        return data + b"#" if self.name == "forces.py" else data

    monkeypatch.setattr(type(k.Path(k.__file__)), "read_bytes", edited)
    assert k._cache_dir() != before
