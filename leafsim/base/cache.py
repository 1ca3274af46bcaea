"""The on-disk cache of compiled numba kernels, set up at the first kernel import (never when
``leafsim`` itself is imported).

numba checks a cached kernel only against its own file: a kernel that calls one from another
file (pbd → blocked, scalar) keeps the callee's old machine code after only the callee's file
changed — stale results, or a crash where an array's type or length changed (seen in this
project's tests).  So the cache lives in a folder named after a hash of every leafsim source
that compiles kernels, inside the platform's cache folder (``$XDG_CACHE_HOME/leafsim/numba``,
``~/.cache/leafsim/numba``, ``~/Library/Caches/leafsim/numba`` or
``%LOCALAPPDATA%\\leafsim\\numba``): any change starts from a clean cache.  The folder in use is
touched at every set-up; beyond :data:`NUMBA_CACHES_KEPT` folders, those idle for
:data:`NUMBA_CACHE_IDLE_S` go, oldest first.  A ``NUMBA_CACHE_DIR`` chosen by the user wins.
Anything that fails here (no home, an unreadable source, a read-only disk) leaves numba's
default (``__pycache__`` beside each file).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

#: compiled-kernel caches kept side by side (one per version of the kernel sources) …
NUMBA_CACHES_KEPT = 4
#: … of those not used for this long [s] (a folder in use is touched at every set-up)
NUMBA_CACHE_IDLE_S = 86400.0

_configured: str | None = None


def user_cache_dir() -> Path:
    """The platform's per-user cache folder for leafsim (not created here)."""
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "leafsim"


def kernel_sources_digest() -> str:
    """A hash of every leafsim source file that compiles numba kernels (16 hex digits)."""
    here = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for p in sorted(here.rglob("*.py")):
        if not p.is_file() or p.name.startswith(".#"):  # editor lock files, dangling links
            continue
        data = p.read_bytes()
        if b"numba" in data:
            h.update(str(p.relative_to(here)).encode() + b"\0" + data)
    return h.hexdigest()[:16]


def configure_numba_cache() -> str | None:
    """Point numba's cache at the folder for today's kernel sources (created now) and prune old
    ones; returns the folder (None: numba's default).  Idempotent; called by every module that
    compiles kernels, before its first ``@njit(cache=True)``."""
    global _configured
    if _configured is not None:
        return _configured or None
    import numba

    if os.environ.get("NUMBA_CACHE_DIR"):
        _configured = os.environ["NUMBA_CACHE_DIR"]
        return _configured
    try:
        base = user_cache_dir() / "numba"
        target = base / kernel_sources_digest()
        target.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=target):  # writable? (a private file: no race)
            pass
        os.utime(target)
    except (OSError, RuntimeError, KeyError):
        _configured = ""
        return None
    numba.config.CACHE_DIR = str(target)
    os.environ["NUMBA_CACHE_DIR"] = str(target)  # child processes (scene workers) share it
    _configured = str(target)
    _prune(base, target)
    return _configured


def _prune(base: Path, keep: Path) -> None:
    try:
        now = time.time()
        old = sorted((d for d in base.iterdir() if d.is_dir() and d != keep), key=lambda d: d.stat().st_mtime)
        excess = len(old) - (NUMBA_CACHES_KEPT - 1)
        for d in old[:max(excess, 0)]:
            if now - d.stat().st_mtime > NUMBA_CACHE_IDLE_S:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass
