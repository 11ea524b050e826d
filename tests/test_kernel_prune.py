"""Compile-cache folders of other versions of the kernel sources are removed once unused
for a while, by the command line (not by `import hybrid`)."""

from __future__ import annotations

import os
import subprocess
import sys

from hybrid.kernel import prune_old_caches

DAY = 86400.0


def _folder(base, name, last_used):
    folder = base / name
    (folder / "index").mkdir(parents=True)
    (folder / "index" / "kernel.nbi").write_bytes(b"x")
    if last_used is not None:
        (folder / ".last_used").touch()
        os.utime(folder / ".last_used", (last_used, last_used))
    return folder


def test_old_cache_folders_of_other_versions_are_removed_and_nothing_else(tmp_path):
    now = 1_800_000_000.0
    current = tmp_path / "numba-0123456789abcdef"
    old = _folder(tmp_path, "numba-aaaaaaaaaaaaaaaa", now - 31 * DAY)
    recent = _folder(tmp_path, "numba-bbbbbbbbbbbbbbbb", now - 29 * DAY)
    unmarked_old = _folder(tmp_path, "numba-cccccccccccccccc", None)  # from before the marks: its own mtime
    os.utime(unmarked_old, (now - 40 * DAY, now - 40 * DAY))
    other = _folder(tmp_path, "numba-notahash", now - 400 * DAY)  # not one of ours by name
    removed = prune_old_caches(str(current), 30, now)
    assert sorted(removed) == sorted([str(old), str(unmarked_old)])
    assert not old.exists() and not unmarked_old.exists()
    assert recent.exists() and other.exists()
    # the folder in use is marked as used now, and is never a candidate
    assert (current / ".last_used").stat().st_mtime == now
    assert prune_old_caches(str(current), 0, now + 10 * DAY) == [str(recent)]
    assert current.exists()


def test_the_command_line_prunes_and_import_does_not(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    old = _folder(tmp_path, "numba-aaaaaaaaaaaaaaaa", 1_000_000_000.0)
    where = "import hybrid.kernel as k; print(k.CACHE_DIR)"
    current = subprocess.run([sys.executable, "-c", where], capture_output=True, text=True, env=env,
                             check=True).stdout.strip()
    mark = os.path.join(current, ".last_used")
    assert old.exists() and not os.path.exists(mark)  # import hybrid: nothing marked, nothing removed
    subprocess.run([sys.executable, "-m", "hybrid", "--help"], capture_output=True, env=env, check=True)
    assert not old.exists()
    assert os.path.exists(mark)
