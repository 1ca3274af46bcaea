"""leafsim — procedural leaves and a physically based simulation of how they age."""

import hashlib
import os
import shutil
import sys
from pathlib import Path

__version__ = "0.1.0"

#: Repository root (configs/, images/, shaders/ live here).
ROOT = Path(__file__).resolve().parent.parent

#: compiled-kernel caches kept side by side (one per version of the kernel sources)
NUMBA_CACHES_KEPT = 4


def _numba_cache_dir() -> None:
    """Point numba's on-disk cache at a folder named after a hash of every leafsim source that
    compiles kernels, unless the user chose one (``NUMBA_CACHE_DIR``) or numba is already
    imported (it has read its settings then).

    numba checks a cached kernel only against its own file: a kernel that calls one from
    another file (pbd → blocked, scalar) keeps the callee's old machine code after only the
    callee's file changed — stale results, or a crash where an array's type or length
    changed (seen in this project's tests).  One folder per version of all kernel sources
    makes any change start from a clean cache; the oldest folders beyond
    :data:`NUMBA_CACHES_KEPT` are removed.  Where no cache folder can be written, numba's
    default (``__pycache__`` beside each file) stays."""
    if "NUMBA_CACHE_DIR" in os.environ or "numba" in sys.modules:
        return
    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(here.rglob("*.py")):
        data = p.read_bytes()
        if b"numba" in data:
            h.update(str(p.relative_to(here)).encode() + b"\0" + data)
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "leafsim" / "numba"
    target = base / h.hexdigest()[:16]
    try:
        target.mkdir(parents=True, exist_ok=True)
        probe = target / ".writable"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return
    os.environ["NUMBA_CACHE_DIR"] = str(target)
    try:  # keep the newest few versions
        old = sorted((d for d in base.iterdir() if d.is_dir() and d != target), key=lambda d: d.stat().st_mtime)
        for d in old[:max(len(old) - (NUMBA_CACHES_KEPT - 1), 0)]:
            shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


_numba_cache_dir()
