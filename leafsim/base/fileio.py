"""Safe file input and output.

Output: a temporary file in the target folder, fsync, then os.replace — an interrupted export
never leaves a half-written file — and only ever onto a writable regular file: a device, a named
pipe, a socket, a folder, a symbolic link (which could point anywhere, another user's file or
the input itself) or a read-only file at the target path is refused, never replaced or written
through.  Folders on the way to the target may be links.  :func:`check_output` tells before any expensive work whether
an output can be written (the folder exists and takes a file, the target is a regular file or
nothing, the disk has room).

Input: :func:`regular_input` accepts only a regular file of bounded size (a named pipe would
block the reader for ever, ``/dev/zero`` never ends), and :func:`read_json` refuses duplicate
keys (the last one would silently win).  Every failure is one LeafsimError line naming the path.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError


def _public_mode() -> int:
    """The mode a plain open() would give (0o666 minus the umask; mkstemp makes 0o600), writable
    by its owner whatever the umask, so leafsim can replace its own file later (a checkpoint,
    a re-run scene)."""
    mask = os.umask(0)
    os.umask(mask)
    return (0o666 & ~mask) | stat.S_IWUSR


#: the largest JSON file (species config, scene, parameter set) read [bytes]
MAX_JSON_BYTES = 32 * 2**20
#: the largest image file read [bytes]
MAX_IMAGE_BYTES = 512 * 2**20
#: an output is refused when its disk has less free space than this plus what it needs [bytes]
MIN_FREE_BYTES = 2**20

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a named pipe"), (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str:
    for test, name in _KINDS:
        if test(mode):
            return name
    return "not a regular file"


def _os_reason(e: OSError) -> str:
    if e.errno == errno.ELOOP:
        return "a loop of symbolic links"
    if e.errno == errno.ENOSPC:
        return "no space left on the device"
    return e.strerror or str(e)


def output_target(path: str | os.PathLike, what: str = "file") -> Path:
    """The file ``path`` will be written as; LeafsimError when something that is not a
    writable regular file is there (it is never replaced): a folder, a device, a named pipe, a
    socket, a symbolic link (live, broken or looping) or a file without write permission."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except OSError as e:
        reason = no_folder(path.parent) if e.errno == errno.ENOTDIR else _os_reason(e)
        raise LeafsimError(f"{path}: cannot write {what} ({reason})") from None
    if stat.S_ISLNK(st.st_mode):
        try:
            os.stat(path)
            kind = "a symbolic link"
        except FileNotFoundError:
            kind = "a broken symbolic link"
        except OSError as e:
            kind = _os_reason(e)
        raise LeafsimError(f"{path}: cannot write {what} (it is {kind}; only a regular file is ever replaced, "
                           "never written through a link)")
    if not stat.S_ISREG(st.st_mode):
        raise LeafsimError(f"{path}: cannot write {what} (it is {_kind(st.st_mode)}; only a regular file is ever replaced)")
    if not st.st_mode & 0o222 or (os.geteuid() != 0 and not os.access(path, os.W_OK)):
        # a rename needs only the folder's permission: the file's own is checked here (root by its mode bits)
        raise LeafsimError(f"{path}: cannot write {what} (the file is read-only; only a writable file is ever replaced)")
    return path


def check_output(path: str | os.PathLike, what: str = "file", need_bytes: int = 0, folder: bool = False) -> Path:
    """Check an output before any work: its folder exists, is a folder and takes a new file (a
    probe file is made and removed: ``/proc`` and read-only mounts fail here, not after the
    build); the target is a writable regular file or nothing (:func:`output_target`;
    ``folder=True``: a folder or nothing); the disk has ``need_bytes`` + 1 MiB free.  Returns
    the path to write."""
    path = Path(path)
    if folder:
        if path.exists() and not path.is_dir():
            raise LeafsimError(f"{path}: cannot write {what} (exists and is not a folder)")
        target, parent = path, (path if path.is_dir() else path.parent)
    else:
        target = output_target(path, what)
        parent = target.parent
    parent = parent if str(parent) else Path(".")
    if not parent.is_dir():
        raise LeafsimError(f"{path}: cannot write {what} ({no_folder(parent)})")
    try:
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as e:
        raise LeafsimError(f"{path}: cannot write {what} (cannot create a file in {parent}: {_os_reason(e)})") from None
    try:
        vfs = os.statvfs(parent)
        free = vfs.f_bavail * vfs.f_frsize
    except (OSError, AttributeError):
        free = None
    if free is not None and free < need_bytes + MIN_FREE_BYTES:
        raise LeafsimError(f"{path}: cannot write {what} (only {free / 2**20:.1f} MiB free on its disk, "
                           f"{(need_bytes + MIN_FREE_BYTES) / 2**20:.1f} MiB needed)")
    return target


def no_folder(folder: Path) -> str:
    """Why ``folder`` (not a folder) cannot take a file: it is missing, or it or a folder above
    it is something else (a file, a named pipe)."""
    p = Path(folder)
    while True:
        try:
            st = os.stat(p)
        except OSError:
            if p.parent == p:
                break
            p = p.parent
            continue
        if not stat.S_ISDIR(st.st_mode):
            return f"{p} is {'a file' if stat.S_ISREG(st.st_mode) else _kind(st.st_mode)}, not a folder"
        break
    return f"folder {folder} does not exist"


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether two paths name one file (the same inode when both exist, else the same real path)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.realpath(a) == os.path.realpath(b)


def not_an_input(path: str | os.PathLike, inputs, option: str) -> None:
    """LeafsimError when the output ``path`` is one of the ``inputs`` (an outline drawn over the
    photo it was traced from would replace the photo)."""
    for src in inputs:
        if src is not None and same_file(path, src):
            raise LeafsimError(f"{option} {path}: that is the input {src} (expected another file; it would be replaced)")


def regular_input(path: str | os.PathLike, what: str = "file", max_bytes: int = MAX_JSON_BYTES) -> Path:
    """``path`` if it is a readable regular file of at most ``max_bytes``; else LeafsimError
    naming what it is (missing, a folder, a device, a named pipe, a link loop, too large)."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise LeafsimError(f"{path}: {what} not found") from None
    except OSError as e:
        raise LeafsimError(f"{path}: cannot read {what} ({_os_reason(e)})") from None
    if not stat.S_ISREG(st.st_mode):
        raise LeafsimError(f"{path}: cannot read {what} (it is {_kind(st.st_mode)}, expected a regular file)")
    if st.st_size > max_bytes:
        raise LeafsimError(f"{path}: {what} is {st.st_size / 2**20:.0f} MiB, more than the {max_bytes / 2**20:.0f} MiB "
                           f"leafsim reads")
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes, what: str = "file") -> Path:
    """Write ``data`` to ``path`` atomically (onto a regular file or nothing); returns the path."""
    path = output_target(path, what)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise LeafsimError(f"{path}: cannot write {what} ({no_folder(folder)})")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as e:
        raise LeafsimError(f"{path}: cannot write {what} ({_os_reason(e)})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _public_mode())
        output_target(path, what)  # the target may have changed kind while we wrote
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError):
            raise LeafsimError(f"{path}: cannot write {what} ({_os_reason(e)})") from None
        raise
    return path


def write_png_atomic(path: str | os.PathLike, img: np.ndarray, rgb: bool = False) -> Path:
    """Encode ``img`` (BGR, or RGB when ``rgb``; uint8, 2D/3/4 channels) as PNG atomically."""
    import cv2

    arr = np.ascontiguousarray(img)
    if rgb and arr.ndim == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGB2BGR if arr.shape[2] == 3 else cv2.COLOR_RGBA2BGRA)
    ok, buf = cv2.imencode(".png", arr)
    if not ok:
        raise LeafsimError(f"{path}: cannot encode PNG")
    return atomic_write_bytes(path, buf.tobytes(), "PNG")


def remove_stale_temps(path: str | os.PathLike) -> int:
    """Delete temporaries that :func:`atomic_write_bytes` left for ``path`` (a glob pattern such
    as ``out/frame_*.png`` works too) when a process was killed (SIGKILL) mid-write; returns how
    many.  Only names of the form ``.<name>.<random>.tmp`` next to the target are touched."""
    path = Path(path)
    n = 0
    for tmp in path.parent.glob(f".{path.name}.*.tmp"):
        try:
            tmp.unlink()
            n += 1
        except OSError:
            pass
    return n


def npz_bytes(arrays: dict) -> bytes:
    """``arrays`` (name → array) as the bytes of a compressed ``.npz`` that depend only on the
    data: every member carries the same fixed timestamp (``np.savez`` stamps the clock time),
    so the same arrays always give the same file (reproducible batch outputs)."""
    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asanyarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, member.getvalue())
    return buf.getvalue()


def _no_duplicates(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Duplicate(k)
        out[k] = v
    return out


class _Duplicate(ValueError):
    pass


class _TooLong(ValueError):
    pass


#: the longest integer a JSON input may write: below Python's own limit of 4300 digits, beyond
#: which parsing failed with an internal error (shorter huge numbers reach the checks of their
#: key, which name it)
MAX_INT_DIGITS = 4000


def read_json(path: str | os.PathLike, what: str = "file", max_bytes: int = MAX_JSON_BYTES):
    """Parse the JSON file ``path``; LeafsimError (one line naming the file and, for bad JSON,
    the line and column) when it is missing, not a regular file, larger than ``max_bytes``,
    unreadable, not UTF-8 text (a UTF-8 byte-order mark is allowed; UTF-16 is named),
    malformed, nested too deeply or names a key twice in one object."""
    import json

    path = regular_input(path, what, max_bytes)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise LeafsimError(f"{path}: cannot read {what} ({_os_reason(e)})") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise LeafsimError(f"{path}: {what} is UTF-16 text, expected UTF-8 (save it as UTF-8)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise LeafsimError(f"{path}: {what} is not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); "
                           "expected a UTF-8 JSON file") from None
    def whole(digits: str) -> int:
        if len(digits.lstrip("-")) > MAX_INT_DIGITS:
            raise _TooLong(digits[:12])
        return int(digits)

    try:
        return json.loads(text, object_pairs_hook=_no_duplicates, parse_int=whole)
    except _TooLong as e:
        raise LeafsimError(f"{path}: an integer of more than {MAX_INT_DIGITS} digits ({e.args[0]}…): expected "
                           f"numbers a leafsim {what} can hold") from None
    except _Duplicate as e:
        raise LeafsimError(f"{path}: duplicate key '{e.args[0]}' (a JSON object names each key once; the "
                           "second would silently replace the first)") from None
    except json.JSONDecodeError as e:
        raise LeafsimError(f"{path}: malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except RecursionError:
        raise LeafsimError(f"{path}: malformed JSON: nested too deeply (expected a leafsim {what})") from None
