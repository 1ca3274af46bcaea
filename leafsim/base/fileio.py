"""Atomic file output: a temporary file in the target folder, fsync, then os.replace.

An interrupted export never leaves a half-written file; a missing or unwritable folder
raises LeafsimError naming the path.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from leafsim.base.errors import LeafsimError


def _public_mode() -> int:
    """The mode a plain open() would give (0o666 minus the umask); mkstemp makes 0o600."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write_bytes(path: str | os.PathLike, data: bytes, what: str = "file") -> Path:
    """Write ``data`` to ``path`` atomically; returns the path."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise LeafsimError(f"{path}: cannot write {what} (folder {folder} does not exist)")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    except OSError as e:
        raise LeafsimError(f"{path}: cannot write {what} ({e.strerror or e})") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _public_mode())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(e, OSError):
            raise LeafsimError(f"{path}: cannot write {what} ({e.strerror or e})") from None
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


def read_json(path: str | os.PathLike, what: str = "file"):
    """Parse the JSON file ``path``; LeafsimError (one line naming the file and, for bad JSON,
    the line and column) when it is missing, a folder, unreadable, not UTF-8 text (a UTF-8
    byte-order mark is allowed; UTF-16 is named), malformed or nested too deeply."""
    import json

    path = Path(path)
    if path.is_dir():
        raise LeafsimError(f"{path}: {what} is a folder, expected a JSON file")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise LeafsimError(f"{path}: {what} not found") from None
    except OSError as e:
        raise LeafsimError(f"{path}: cannot read {what} ({e.strerror or e})") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise LeafsimError(f"{path}: {what} is UTF-16 text, expected UTF-8 (save it as UTF-8)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise LeafsimError(f"{path}: {what} is not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); "
                           "expected a UTF-8 JSON file") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise LeafsimError(f"{path}: malformed JSON at line {e.lineno} column {e.colno}: {e.msg}") from None
    except RecursionError:
        raise LeafsimError(f"{path}: malformed JSON: nested too deeply (expected a leafsim {what})") from None
