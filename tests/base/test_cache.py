"""numba's on-disk cache lives in a folder keyed to the kernel sources (leafsim/base/cache.py),
set up by the first kernel import, never by ``import leafsim``: a kernel that calls one in
another file can then never keep the callee's old machine code."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from leafsim.base import cache

SHOW = "import os, sys; {pre}import leafsim.sim.kernels.pbd; print(os.environ.get('NUMBA_CACHE_DIR', ''))"


def _run(code: str, tmp_path: Path, **env) -> subprocess.CompletedProcess:
    e = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    e.update(XDG_CACHE_HOME=str(tmp_path), **env)
    return subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, cwd=str(tmp_path))


def _cache_dir(tmp_path: Path, pre: str = "", **env) -> str:
    out = _run(SHOW.format(pre=pre), tmp_path, **env)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_importing_leafsim_touches_no_cache(tmp_path):
    out = _run("import os, leafsim, leafsim.cli; print(os.environ.get('NUMBA_CACHE_DIR', ''))", tmp_path)
    assert out.returncode == 0 and out.stdout.strip() == ""
    assert not (tmp_path / "leafsim").exists()


def test_cache_folder_is_keyed_to_the_sources(tmp_path):
    d = Path(_cache_dir(tmp_path))
    assert d.parent == tmp_path / "leafsim" / "numba" and len(d.name) == 16 and d.is_dir()
    assert d.name == cache.kernel_sources_digest()
    assert _cache_dir(tmp_path) == str(d)  # the same sources, the same folder
    assert _cache_dir(tmp_path, pre="import numba; ") == str(d)  # numba imported first: set all the same


def test_old_idle_cache_folders_are_pruned(tmp_path):
    """Beyond NUMBA_CACHES_KEPT folders, the oldest idle ones go; a folder used recently (another
    checkout's, touched at its set-up) stays however many there are."""
    base = tmp_path / "leafsim" / "numba"
    for k in range(6):
        (base / f"old{k}").mkdir(parents=True)
        t = time.time() - 2 * cache.NUMBA_CACHE_IDLE_S + k
        os.utime(base / f"old{k}", (t, t))
    (base / "busy").mkdir()  # idle for less than a day
    d = Path(_cache_dir(tmp_path))
    left = sorted(p.name for p in base.iterdir())
    assert d.name in left and "busy" in left
    assert {"old4", "old5"} <= set(left) and not {"old0", "old1", "old2", "old3"} & set(left)
    assert len(left) == cache.NUMBA_CACHES_KEPT


def test_no_home_or_unwritable_cache_falls_back_quietly(tmp_path):
    (tmp_path / "leafsim").write_text("not a folder")  # root writes anywhere: a file blocks the folder
    assert _cache_dir(tmp_path) == ""
    e = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "XDG_CACHE_HOME", "HOME")}
    out = subprocess.run([sys.executable, "-c", SHOW.format(pre="")], env=e, capture_output=True, text=True,
                         cwd=str(tmp_path))
    assert out.returncode == 0  # Path.home() may fail without HOME: the kernels still import


def test_a_chosen_cache_wins(tmp_path):
    assert _cache_dir(tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "mine")) == str(tmp_path / "mine")

