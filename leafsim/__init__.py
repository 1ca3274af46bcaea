"""leafsim — procedural leaves and a physically based simulation of how they age."""

import hashlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

__version__ = "0.1.0"

#: Repository root (configs/, images/, shaders/ live here).
ROOT = Path(__file__).resolve().parent.parent

#: compiled-kernel caches kept side by side (one per version of the kernel sources) …
NUMBA_CACHES_KEPT = 4
#: … of those not used for this long [s] (a folder in use is touched at every import)
NUMBA_CACHE_IDLE_S = 86400.0


def _numba_cache_dir() -> None:
    """Point numba's on-disk cache at a folder named after a hash of every leafsim source that
    compiles kernels, unless the user chose one (``NUMBA_CACHE_DIR``) or numba is already
    imported (it has read its settings then).

    numba checks a cached kernel only against its own file: a kernel that calls one from
    another file (pbd → blocked, scalar) keeps the callee's old machine code after only the
    callee's file changed — stale results, or a crash where an array's type or length
    changed (seen in this project's tests).  One folder per version of all kernel sources
    makes any change start from a clean cache.  The folder in use is touched at every import;
    beyond :data:`NUMBA_CACHES_KEPT` folders, those idle for :data:`NUMBA_CACHE_IDLE_S` go,
    oldest first.  Anything that fails here (no home, an unreadable source, a read-only disk)
    leaves numba's default (``__pycache__`` beside each file)."""
    if os.environ.get("NUMBA_CACHE_DIR") or "numba" in sys.modules:
        return
    try:
        here = Path(__file__).resolve().parent
        h = hashlib.sha256()
        for p in sorted(here.rglob("*.py")):
            if not p.is_file() or p.name.startswith(".#"):  # editor lock files, dangling links
                continue
            data = p.read_bytes()
            if b"numba" in data:
                h.update(str(p.relative_to(here)).encode() + b"\0" + data)
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "leafsim" / "numba"
        target = base / h.hexdigest()[:16]
        target.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=target):  # writable? (a private file: no race)
            pass
        os.utime(target)
    except (OSError, RuntimeError, KeyError):
        return
    os.environ["NUMBA_CACHE_DIR"] = str(target)
    try:
        now = time.time()
        old = sorted((d for d in base.iterdir() if d.is_dir() and d != target), key=lambda d: d.stat().st_mtime)
        excess = len(old) - (NUMBA_CACHES_KEPT - 1)
        for d in old[:max(excess, 0)]:
            if now - d.stat().st_mtime > NUMBA_CACHE_IDLE_S:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


_numba_cache_dir()
