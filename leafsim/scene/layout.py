"""Where a scene writes each leaf: ``OUT/leaves/NAME/``."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

from leafsim.base.errors import LeafsimError

#: the files a leaf's folder holds (:func:`leafsim.scene.job.run_leaf`), and the temporaries of
#: their atomic writes (``.NAME.XXXXXXXX.tmp``)
_LEAF_FILES = re.compile(r"(view\.npz|state\.npz|stats\.jsonl|lod\.json|done\.json|leaf(_photo|_baked|_baked_normal|_baked_lower|_baked_normal_lower)?\.(glb|gltf|bin|obj|mtl|ply|png))")
_FRAME_FILES = re.compile(r"state_\d{6}\.npz")
_TEMP = re.compile(r"\..+\.tmp")


def leaf_dir(out: Path, name: str) -> Path:
    return Path(out) / "leaves" / name


def leaf_folder_entries(folder: Path) -> list[Path]:
    """The files leafsim wrote in a leaf's folder (``frames/`` last), to be replaced by a new run
    of that leaf; LeafsimError naming the first entry that leafsim did not write (a folder of
    the user's, a named pipe, a symlink, another file), so that nothing but leafsim's own regular
    files is ever removed.  [] when there is no folder."""
    folder = Path(folder)
    try:
        st = os.lstat(folder)
    except FileNotFoundError:
        return []
    except OSError as e:
        raise LeafsimError(f"{folder}: cannot read the leaf's folder ({e.strerror})") from None
    if not stat.S_ISDIR(st.st_mode):
        raise LeafsimError(f"{folder}: a leaf's output is a folder, and a {_kind(st.st_mode)} is there; "
                           "move it away or choose another --out")
    found: list[Path] = []
    frames = folder / "frames"
    for parent, pattern in ((folder, _LEAF_FILES), (frames, _FRAME_FILES)):
        if parent is frames:
            try:
                fst = os.lstat(frames)
            except FileNotFoundError:
                continue
            if not stat.S_ISDIR(fst.st_mode):
                raise LeafsimError(f"{frames}: expected leafsim's frames folder, found a {_kind(fst.st_mode)}; move it away")
        for entry in sorted(os.scandir(parent), key=lambda e: e.name):
            p = Path(entry.path)
            if parent is folder and entry.name == "frames":
                continue
            mode = os.lstat(p).st_mode
            if not (stat.S_ISREG(mode) and (pattern.fullmatch(entry.name) or _TEMP.fullmatch(entry.name))):
                raise LeafsimError(f"{p}: not a file leafsim writes in a leaf's folder (a {_kind(mode)}); "
                                   "leafsim replaces a leaf's files only when the folder holds nothing else: move it away")
            found.append(p)
    return found


def clear_leaf_folder(folder: Path) -> None:
    """Remove the files leafsim wrote in a leaf's folder (:func:`leaf_folder_entries`, which
    refuses anything else), then the emptied folders."""
    folder = Path(folder)
    for p in leaf_folder_entries(folder):
        p.unlink()
    for d in (folder / "frames", folder):
        try:
            d.rmdir()
        except FileNotFoundError:
            pass


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISLNK, "symlink"), (stat.S_ISDIR, "folder"), (stat.S_ISFIFO, "named pipe"),
                       (stat.S_ISSOCK, "socket"), (stat.S_ISCHR, "device"), (stat.S_ISBLK, "device"),
                       (stat.S_ISREG, "file")):
        if test(mode):
            return name
    return "special file"
