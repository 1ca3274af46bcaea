"""What made an output: leafsim's version and source commit, the libraries that compute it, the
machine, and (per command) the species, config and effective parameters.  Every ``--json``
object carries it as ``provenance`` (and ``leafsim run``'s ``final.npz`` as ``meta``), so a
number taken into a paper says how to make it again.  Deterministic: no clock, so the same
command gives the same bytes."""

from __future__ import annotations

import platform
import subprocess
import sys
from pathlib import Path

_COMMIT: list = []


def source_commit() -> str | None:
    """The git commit of the checkout leafsim runs from, with ``+changes`` when its tracked
    files differ from it; None for an installed copy (no checkout around it) or without git."""
    if not _COMMIT:
        root = Path(__file__).resolve().parents[2]
        value = None
        if (root / ".git").exists():
            try:
                git = ["git", "--no-optional-locks", "-C", str(root)]  # never takes the index lock
                head = subprocess.run([*git, "rev-parse", "HEAD"], capture_output=True, text=True, timeout=2)
                if head.returncode == 0:
                    value = head.stdout.strip()
                    dirty = subprocess.run([*git, "status", "--porcelain", "--untracked-files=no"],
                                           capture_output=True, text=True, timeout=2)
                    if dirty.returncode == 0 and dirty.stdout.strip():
                        value += "+changes"
            except (OSError, subprocess.SubprocessError):
                value = None
        _COMMIT.append(value)
    return _COMMIT[0]


def provenance(**extra) -> dict:
    """The version, commit, library versions and machine, with ``extra`` (species, config,
    parameters ...) added."""
    import numba
    import numpy

    from leafsim import __version__

    return {"leafsim": __version__, "commit": source_commit(), "python": platform.python_version(),
            "numpy": numpy.__version__, "numba": numba.__version__, "machine": platform.machine(),
            "system": platform.system(), **extra}


def command_line(argv=None) -> str:
    """The command as typed after ``leafsim``, quoted as a shell would need it (for the record)."""
    import shlex

    args = sys.argv[1:] if argv is None else argv
    return shlex.join(str(a) for a in args)
