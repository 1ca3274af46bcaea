"""numba's on-disk cache lives in a folder keyed to the kernel sources (leafsim/__init__.py):
a kernel that calls one in another file can then never keep the callee's old machine code."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import leafsim

SHOW = "import os, sys; {pre}import leafsim; print(os.environ.get('NUMBA_CACHE_DIR', ''))"


def _cache_dir(tmp_path: Path, pre: str = "", **env) -> str:
    e = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    e.update(XDG_CACHE_HOME=str(tmp_path), **env)
    out = subprocess.run([sys.executable, "-c", SHOW.format(pre=pre)], env=e, capture_output=True, text=True,
                         check=True, cwd=str(leafsim.ROOT))
    return out.stdout.strip()


def test_cache_folder_is_keyed_to_the_sources(tmp_path):
    d = Path(_cache_dir(tmp_path))
    assert d.parent == tmp_path / "leafsim" / "numba" and len(d.name) == 16 and d.is_dir()
    assert _cache_dir(tmp_path) == str(d)  # the same sources, the same folder


def test_old_idle_cache_folders_are_pruned(tmp_path):
    """Beyond NUMBA_CACHES_KEPT folders, the oldest idle ones go; a folder used recently (another
    checkout's, touched at its imports) stays however many there are."""
    base = tmp_path / "leafsim" / "numba"
    for k in range(6):
        (base / f"old{k}").mkdir(parents=True)
        t = time.time() - 2 * leafsim.NUMBA_CACHE_IDLE_S + k
        os.utime(base / f"old{k}", (t, t))
    (base / "busy").mkdir()  # idle for less than a day
    d = Path(_cache_dir(tmp_path))
    left = sorted(p.name for p in base.iterdir())
    assert d.name in left and "busy" in left
    assert {"old4", "old5"} <= set(left) and not {"old0", "old1", "old2", "old3"} & set(left)
    assert len(left) == leafsim.NUMBA_CACHES_KEPT


def test_no_home_or_unwritable_cache_falls_back_quietly(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        if os.access(ro, os.W_OK):  # root writes anyway: make the cache path a file instead
            (tmp_path / "leafsim").write_text("not a folder")
            assert _cache_dir(tmp_path) == ""
        else:
            assert _cache_dir(ro) == ""
    finally:
        ro.chmod(0o700)
    e = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "HOME")}
    out = subprocess.run([sys.executable, "-c", SHOW.format(pre="")], env=e, capture_output=True, text=True,
                         cwd=str(leafsim.ROOT))
    assert out.returncode == 0  # Path.home() may fail without HOME: leafsim still imports


def test_a_chosen_cache_or_an_earlier_numba_wins(tmp_path):
    assert _cache_dir(tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "mine")) == str(tmp_path / "mine")
    assert _cache_dir(tmp_path, pre="import numba; ") == ""  # numba has read its settings already
