"""Reading a leaf photo: any image file (alpha kept) with a clear error naming the file, a
working copy downscaled to the pixel limit, and the mask morphology helpers."""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
import threading

import cv2
import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import MAX_IMAGE_BYTES, regular_input

_DEBUG = False
#: a working copy smaller than this on its long side is too coarse to trace [px]
MIN_WORKING_SIDE = 300


#: the most pixels a photo may have (a 50 MP camera gives 50 million; a small file can claim
#: billions: a 0.5 MB 1-bit PNG of 65 000 × 65 000 took gigabytes to decode)
MAX_DECODE_PIXELS = 150_000_000


def _header_size(data: np.ndarray) -> tuple[int, int] | None:
    """(width, height) the header of a PNG, JPEG, TIFF, BMP, WebP or PNM file claims, before
    decoding; None when it cannot be read there (another kind, or a header out of reach)."""
    b = data[:1 << 21].tobytes()  # the frame header follows the metadata segments (EXIF ≤ 64 kB each)
    if b[:8] == b"\x89PNG\r\n\x1a\n" and b[12:16] == b"IHDR":
        return int.from_bytes(b[16:20], "big"), int.from_bytes(b[20:24], "big")
    if b[:2] == b"\xff\xd8":  # the frame header follows the metadata segments, however long they are
        i, n = 2, data.size
        while i + 9 <= n and data[i] == 0xFF:
            while i + 1 < n and data[i + 1] == 0xFF:  # fill bytes before a marker
                i += 1
            if i + 9 > n:
                break
            head = data[i:i + 9].tobytes()
            marker, seg = head[1], int.from_bytes(head[2:4], "big")
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                return int.from_bytes(head[7:9], "big"), int.from_bytes(head[5:7], "big")
            i += 2 + seg
        return None
    if b[:2] == b"BM" and len(b) >= 26:
        return abs(int.from_bytes(b[18:22], "little", signed=True)), abs(int.from_bytes(b[22:26], "little", signed=True))
    if b[:4] in (b"II*\x00", b"MM\x00*"):  # its directory may sit anywhere, often at the end
        return _tiff_size(data, "little" if b[:2] == b"II" else "big")
    if b[:4] == b"RIFF" and b[8:12] == b"WEBP" and len(b) >= 30:
        kind = b[12:16]
        if kind == b"VP8 ":
            return int.from_bytes(b[26:28], "little") & 0x3FFF, int.from_bytes(b[28:30], "little") & 0x3FFF
        if kind == b"VP8L":
            v = int.from_bytes(b[21:25], "little")
            return (v & 0x3FFF) + 1, ((v >> 14) & 0x3FFF) + 1
        if kind == b"VP8X":
            return int.from_bytes(b[24:27], "little") + 1, int.from_bytes(b[27:30], "little") + 1
        return None
    if len(b) > 2 and b[:1] == b"P" and b[1:2] in b"123456":
        words = []
        for line in b[2:4096].split(b"\n"):
            words += line.split(b"#")[0].split()
            if len(words) >= 2:
                try:
                    return int(words[0]), int(words[1])
                except ValueError:
                    return None
    return None


def _tiff_size(data: np.ndarray, order: str) -> tuple[int, int] | None:
    """Width and height of a TIFF's first image (tags 256 and 257 of its first IFD), read where
    the header points, anywhere in the file."""
    def num(at: int, n: int) -> int | None:
        return int.from_bytes(data[at:at + n].tobytes(), order) if 0 <= at and at + n <= data.size else None

    off = num(4, 4)
    count = None if off is None else num(off, 2)
    if count is None:
        return None
    size = {}
    for k in range(count):
        e = off + 2 + 12 * k
        tag, typ = num(e, 2), num(e + 2, 2)
        if tag is None or typ is None:
            return None
        if tag in (256, 257):
            size[tag] = num(e + 8, 2) if typ == 3 else num(e + 8, 4)
    return (size[256], size[257]) if len(size) == 2 and None not in size.values() else None


def _quiet_opencv() -> None:
    """OpenCV's decoders print their own complaints on stderr; leafsim says one line instead."""
    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    except AttributeError:
        pass


_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _decoder_stderr():
    """Catch what the image libraries write on the process's stderr while they decode (libpng's
    "PNG input buffer is incomplete", libjpeg's warnings): leafsim says one line instead. Yields
    a list that holds the caught lines afterwards."""
    said: list[str] = []
    # fd 2 is the whole process's: only the main thread (a command) redirects it, one at a time;
    # a worker thread (the window's builds, a Dask worker) decodes without catching
    if threading.current_thread() is not threading.main_thread() or not _STDERR_LOCK.acquire(blocking=False):
        yield said
        return
    saved = tmp = None
    try:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
            tmp = tempfile.TemporaryFile()
            os.dup2(tmp.fileno(), 2)
        except (OSError, ValueError, AttributeError):  # no real stderr, no temporary folder: no catching
            if saved is not None:
                os.close(saved)
            saved = None
        try:
            yield said
        finally:
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
                tmp.seek(0)
                said += [ln.strip() for ln in tmp.read(4096).decode("utf-8", "replace").splitlines() if ln.strip()]
    finally:
        if tmp is not None:
            tmp.close()
        _STDERR_LOCK.release()


def load_image(path: str | os.PathLike) -> np.ndarray:
    """Read a photo as uint8 BGR (h, w, 3) or BGRA (h, w, 4).

    Raises LeafsimError ``<path>: cannot read image (<reason>)`` for a missing, unreadable,
    empty or corrupt file.
    """
    where = str(path)
    # a regular file of bounded size: a named pipe would block the reader, a device never end
    p = regular_input(path, "image", MAX_IMAGE_BYTES)
    try:
        data = np.fromfile(str(p), dtype=np.uint8)
    except OSError as exc:
        raise LeafsimError(f"{where}: cannot read image ({exc.strerror or exc})") from None
    if data.size == 0:
        raise LeafsimError(f"{where}: cannot read image (empty file)")
    size = _header_size(data)
    if size is None:  # decoding first would meet no pixel limit (a 20 000² TIFF of 1.2 MB took 1.7 GB)
        raise LeafsimError(f"{where}: cannot read image (its size is not in a PNG, JPEG, TIFF, BMP, WebP or PNM "
                           "header: another kind of file, or a damaged one)")
    if size[0] * size[1] > MAX_DECODE_PIXELS:
        raise LeafsimError(f"{where}: cannot read image ({size[0]}×{size[1]} pixels, more than "
                           f"{MAX_DECODE_PIXELS // 1_000_000} million: expected a photo of one leaf)")
    _quiet_opencv()
    try:
        with _decoder_stderr() as said:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:  # OpenCV's own limits (pixels, memory)
        raise LeafsimError(f"{where}: cannot read image (OpenCV: {str(exc).strip().splitlines()[-1][:80]})") from None
    if img is None:
        why = f"{said[0][:80]}" if said else "not a PNG/JPEG/TIFF/BMP/WebP image or corrupt data"
        raise LeafsimError(f"{where}: cannot read image ({why})")
    if img.size == 0 or img.shape[0] == 0 or img.shape[1] == 0:
        raise LeafsimError(f"{where}: cannot read image (image has no pixels)")
    if img.dtype != np.uint8:
        if img.dtype == np.uint16:
            img = (img >> 8).astype(np.uint8)
        elif np.issubdtype(img.dtype, np.floating):
            img = np.clip(np.nan_to_num(img) * 255.0, 0, 255).astype(np.uint8)
        else:
            img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 2:  # grey + alpha
        g, a = img[..., 0], img[..., 1]
        img = np.dstack([g, g, g, a])
    elif img.shape[2] > 4:
        img = img[..., :4]
    if min(img.shape[:2]) < 8:
        raise LeafsimError(f"{where}: cannot read image (too small: {img.shape[1]}×{img.shape[0]} pixels)")
    return np.ascontiguousarray(img)


def _disk(d: int) -> np.ndarray:
    d = max(1, int(d) | 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d))


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    cnts, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros_like(mask)
    if cnts:
        cv2.drawContours(out, cnts, -1, 255, thickness=cv2.FILLED)
    return out


def _largest_component(mask: np.ndarray) -> np.ndarray:
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return np.zeros_like(mask)
    k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return np.where(lab == k, 255, 0).astype(np.uint8)


#: :func:`edge_contours` traces a mask this many times enlarged (nearest): its contour runs
#: 1/(2·EDGE_UPSAMPLE) px inside the pixels' edges instead of ½ px (on their centres)
EDGE_UPSAMPLE = 4


def edge_contours(mask: np.ndarray) -> list[np.ndarray]:
    """The outer contours of a 0/255 mask's regions as (k, 2) float arrays in its pixel
    coordinates (x, y), along the pixels' outer edges (within 1/(2·EDGE_UPSAMPLE) px).
    OpenCV's contour joins the boundary pixels' centres, half a pixel inside the region: a
    traced leaf came out ½ px too small all round and a pixel short at every tooth tip (a
    hornbeam margin 4 % short of its photo's).  Traced on the region's bounding box enlarged
    ``EDGE_UPSAMPLE`` times (nearest), so only the leaf's box is enlarged."""
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return []
    k = EDGE_UPSAMPLE
    x0, y0 = int(xs.min()), int(ys.min())
    box = np.ascontiguousarray(mask[y0:int(ys.max()) + 1, x0:int(xs.max()) + 1])
    up = cv2.resize(box, None, fx=k, fy=k, interpolation=cv2.INTER_NEAREST)
    cnts, _ = cv2.findContours(up, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    off = np.array([x0, y0], float)
    return [(c.reshape(-1, 2).astype(np.float64) + 0.5) / k - 0.5 + off for c in cnts]


def working_image(img: np.ndarray, max_pixels: int) -> tuple[np.ndarray, float]:
    """``img`` downscaled (area averaging) to at most ``max_pixels`` pixels, and the factor f
    (working = photo × f; 1.0 when it is small enough).  Segmenting a 20000×20000 photo at full
    size takes minutes and >10 GB; the outline's accuracy needs far fewer pixels."""
    h, w = img.shape[:2]
    if h * w <= max_pixels:
        return img, 1.0
    f = math.sqrt(max_pixels / float(h * w))
    if max(w, h) * f < MIN_WORKING_SIDE:
        raise LeafsimError(f"limits.image_pixels = {max_pixels:,} would trace this {w}×{h} photo on a {int(w * f)}×{int(h * f)} "
                           f"copy, too coarse to find the leaf's outline (≥ {MIN_WORKING_SIDE} px on the long side needed); "
                           "raise limits.image_pixels")
    size = (max(8, int(w * f)), max(8, int(h * f)))
    small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    return small, size[0] / float(w)
