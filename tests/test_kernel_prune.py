"""Compile-cache folders of other versions of hybrid's sources are removed once unused for a while."""

from __future__ import annotations

import os

from hybrid.kernel import CACHE_DIR, _prune_caches

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
    removed = _prune_caches(str(current), 30, now)
    assert sorted(removed) == sorted([str(old), str(unmarked_old)])
    assert not old.exists() and not unmarked_old.exists()
    assert recent.exists() and other.exists()
    # the folder in use is marked as used now, and is never a candidate
    assert (current / ".last_used").stat().st_mtime == now
    assert _prune_caches(str(current), 0, now + 10 * DAY) == [str(recent)]
    assert current.exists()


def test_the_cache_in_use_is_marked_at_import():
    assert os.path.exists(os.path.join(CACHE_DIR, ".last_used"))
