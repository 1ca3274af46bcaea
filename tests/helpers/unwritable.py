"""A folder the code under test cannot write into, whoever runs the suite.

Permission bits do not stop root (CAP_DAC_OVERRIDE), and the suite often runs as root (CI
containers), where a read-only-folder test used to be skipped.  As root, the block runs with the
process's *effective* user and group dropped to ``nobody`` (65534): the kernel then checks the
folder's mode bits as for any user.  The real user stays root, so the ids are restored after
the block.  The ids change for the whole process (every thread), in process because the code
under test holds state a child could not use (a renderer's GL context is not fork-safe; a fresh
interpreter as ``nobody`` may not even read the checkout or the numba cache)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import pytest

NOBODY = 65534


def _root() -> bool:
    return hasattr(os, "geteuid") and os.geteuid() == 0


@contextlib.contextmanager
def unwritable_folder(tmp_path: Path):
    """Yield a folder ``ro`` (mode 0o500 for the user, 0o555 for root's test) that the code
    run inside the ``with`` block cannot create files in.  Not root: ``tmp_path / "ro"``.
    Root: a folder in the system temp dir (pytest's tmp_path is private to root, so ``nobody``
    could not even reach it, which is another failure), owned by root, with the effective
    uid/gid ``nobody`` for the block.  Skips when root may not change its effective ids."""
    if not _root():
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            yield ro
        finally:
            ro.chmod(0o700)
        return
    base = Path(tempfile.mkdtemp(prefix="leafsim-unwritable-"))
    try:
        base.chmod(0o755)  # reachable by nobody
        ro = base / "ro"
        ro.mkdir()
        ro.chmod(0o555)  # root's, readable, not writable by nobody
        gid = os.getegid()
        try:
            os.setegid(NOBODY)
            os.seteuid(NOBODY)
        except PermissionError as e:  # a container without CAP_SETUID/CAP_SETGID
            os.setegid(gid)
            pytest.skip(f"running as root without the right to drop privileges ({e})")
        try:
            assert not os.access(ro, os.W_OK, effective_ids=True) and os.access(ro, os.X_OK, effective_ids=True)
            yield ro
        finally:
            os.seteuid(0)
            os.setegid(gid)
    finally:
        shutil.rmtree(base, ignore_errors=True)
