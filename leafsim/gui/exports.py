"""Where exported frames go, without ever overwriting anything (no imgui, no OpenGL).

* :func:`ensure_folder` creates the export folder (and its parents) when it is missing and
  says so; a file in its place or an unwritable folder is a one-line error.
* :func:`new_take` makes the next numbered folder ``take_001``, ``take_002``, ... for one
  recorded sequence (numbers are never reused, even when older takes were deleted in between
  they continue after the highest one present).
* :func:`free_path` picks ``name.png``, else ``name_2.png``, ``name_3.png``, ...
* :func:`user_path` checks what was typed into a path field (empty, a NUL character) and
  expands ``~``.
* :class:`BackgroundJobs` runs an export the window should not wait for on its own thread.
"""

from __future__ import annotations

import errno
import os
import re
from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output

TAKE_RE = re.compile(r"^take_(\d{3,})$")


def user_path(text, field: str, kind: str = "folder") -> Path:
    """The path typed into the field ``field`` (``~`` expanded); LeafsimError when it is empty
    or holds a NUL character (no file can be named so: the system call would fail with an
    internal error)."""
    text = os.fspath(text)
    if not text.strip():
        raise LeafsimError(f"{field}: empty; expected the path of a {kind}")
    if "\0" in text:
        raise LeafsimError(f"{field} {text!r}: contains a NUL character; expected the path of a {kind}")
    return Path(text).expanduser()


def _reason(e: OSError) -> str:
    if e.errno == errno.ELOOP:
        return "a loop of symbolic links"
    return e.strerror or str(e)


def ensure_folder(folder) -> tuple[Path, bool]:
    """``(absolute folder, created)``; raises LeafsimError when it cannot be used (empty, a
    file, a link to a file, a broken link, a link loop, a name too long, not writable)."""
    f = user_path(folder, "export folder")
    f = f if f.is_absolute() else Path.cwd() / f
    created = False
    try:
        os.stat(f)
        missing = False
    except FileNotFoundError:
        missing = True
    except OSError as e:
        raise LeafsimError(f"export folder {f}: cannot use it ({_reason(e)})") from None
    if missing:
        if os.path.islink(f):
            raise LeafsimError(f"export folder {f} is a broken symbolic link (expected a folder, or nothing: "
                               "it is then created)")
        try:
            f.mkdir(parents=True)
            created = True
        except FileExistsError:
            pass
        except OSError as e:
            raise LeafsimError(f"cannot create export folder {f}: {_reason(e)}") from None
    if not f.is_dir():
        raise LeafsimError(f"export folder {f} is not a folder (a file has that name)")
    if not os.access(f, os.W_OK | os.X_OK):
        raise LeafsimError(f"export folder {f} is not writable")
    check_output(f, "export folder", folder=True)  # takes a file (not /proc, a read-only mount or a full disk)
    return f, created


def new_take(folder: Path) -> Path:
    """Create and return the next ``take_NNN`` folder inside ``folder``."""
    highest = 0
    try:
        names = os.listdir(folder)
    except OSError as e:  # writable but not readable (-wx), or gone since ensure_folder
        raise LeafsimError(f"export folder {folder}: cannot list it ({_reason(e)})") from None
    for name in names:
        m = TAKE_RE.match(name)
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


def free_path(folder: Path, stem: str, suffix: str = ".png", taken=()) -> Path:
    """A path in ``folder`` that does not exist yet and is not in ``taken`` (files being
    written): ``stem.png``, ``stem_2.png``, ..."""
    p = folder / f"{stem}{suffix}"
    k = 2
    while p.exists() or p in taken:
        p = folder / f"{stem}_{k}{suffix}"
        k += 1
    return p


class BackgroundJobs:
    """Work the window should not wait for (a mesh export bakes its texture for about a
    second), each on its own thread: :meth:`start` runs ``fn()`` there; :meth:`finished`,
    called once a frame, returns the jobs that ended as (tag, result, error message or None);
    :meth:`join` waits for the rest (the window closing must not cut a file short)."""

    def __init__(self):
        self.jobs: list = []

    def start(self, tag, fn) -> None:
        import threading

        job = {"tag": tag, "result": None, "error": None, "done": threading.Event()}

        def work():
            try:
                job["result"] = fn()
            except LeafsimError as e:
                job["error"] = str(e)
            except Exception as e:  # the window must survive anything a job meets
                job["error"] = f"internal error: {type(e).__name__}: {e}"
            finally:
                job["done"].set()

        job["thread"] = threading.Thread(target=work, name=f"leafsim-{tag}", daemon=True)
        self.jobs.append(job)
        job["thread"].start()

    def pending(self, tag=None) -> list:
        return [j["tag"] for j in self.jobs if not j["done"].is_set() and (tag is None or j["tag"] == tag)]

    def finished(self) -> list:
        done = [j for j in self.jobs if j["done"].is_set()]
        self.jobs = [j for j in self.jobs if not j["done"].is_set()]
        return [(j["tag"], j["result"], j["error"]) for j in done]

    def join(self, timeout: float | None = None) -> None:
        for j in self.jobs:
            j["thread"].join(timeout)
