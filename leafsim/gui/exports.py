"""Where exported frames go, without ever overwriting anything (no imgui, no OpenGL).

* :func:`ensure_folder` creates the export folder (and its parents) when it is missing and
  says so; a file in its place or an unwritable folder is a one-line error.
* :func:`new_take` makes the next numbered folder ``take_001``, ``take_002``, ... for one
  recorded sequence (numbers are never reused, even when older takes were deleted in between
  they continue after the highest one present).
* :func:`free_path` picks ``name.png``, else ``name_2.png``, ``name_3.png``, ...
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from leafsim.base.errors import LeafsimError

TAKE_RE = re.compile(r"^take_(\d{3,})$")


def ensure_folder(folder) -> tuple[Path, bool]:
    """``(absolute folder, created)``; raises LeafsimError when it cannot be used."""
    f = Path(folder).expanduser()
    f = f if f.is_absolute() else Path.cwd() / f
    created = False
    if not f.exists():
        try:
            f.mkdir(parents=True)
            created = True
        except FileExistsError:
            pass
        except OSError as e:
            raise LeafsimError(f"cannot create export folder {f}: {e.strerror or e}") from None
    if not f.is_dir():
        raise LeafsimError(f"export folder {f} is not a folder (a file has that name)")
    if not os.access(f, os.W_OK | os.X_OK):
        raise LeafsimError(f"export folder {f} is not writable")
    return f, created


def new_take(folder: Path) -> Path:
    """Create and return the next ``take_NNN`` folder inside ``folder``."""
    highest = 0
    for p in folder.iterdir():
        m = TAKE_RE.match(p.name)
        if m:
            highest = max(highest, int(m.group(1)))
    for k in range(highest + 1, highest + 1000):
        take = folder / f"take_{k:03d}"
        try:
            take.mkdir()
            return take
        except FileExistsError:  # another window took it meanwhile
            continue
        except OSError as e:
            raise LeafsimError(f"cannot create {take}: {e.strerror or e}") from None
    raise LeafsimError(f"{folder}: no free take number")


def free_path(folder: Path, stem: str, suffix: str = ".png") -> Path:
    """A path in ``folder`` that does not exist yet: ``stem.png``, ``stem_2.png``, ..."""
    p = folder / f"{stem}{suffix}"
    k = 2
    while p.exists():
        p = folder / f"{stem}_{k}{suffix}"
        k += 1
    return p
