"""Safe file input and output: only regular files are ever replaced, outputs are checked before
any work, inputs must be bounded regular files, JSON keys are unique."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from leafsim.base import fileio
from leafsim.base.errors import LeafsimError


@pytest.fixture
def specials(tmp_path):
    """A named pipe, a folder, a symbolic-link loop, a link to a regular file."""
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    (tmp_path / "folder.png").mkdir()
    (tmp_path / "loop_a").symlink_to(tmp_path / "loop_b")
    (tmp_path / "loop_b").symlink_to(tmp_path / "loop_a")
    (tmp_path / "real.png").write_bytes(b"old")
    (tmp_path / "link.png").symlink_to(tmp_path / "real.png")
    return tmp_path


def test_a_write_never_replaces_anything_but_a_regular_file(specials):
    for name, kind in (("pipe.png", "named pipe"), ("folder.png", "folder")):
        with pytest.raises(LeafsimError, match=f"it is a {kind}; only a regular file is ever replaced"):
            fileio.atomic_write_bytes(specials / name, b"new")
    assert (specials / "pipe.png").is_fifo() and (specials / "folder.png").is_dir()
    with pytest.raises(LeafsimError, match="a loop of symbolic links"):
        fileio.atomic_write_bytes(specials / "loop_a", b"new")
    # a link is never written through (it could point at anything: the input, another user's file)
    with pytest.raises(LeafsimError, match="it is a symbolic link; only a regular file is ever replaced, never written"):
        fileio.atomic_write_bytes(specials / "link.png", b"new")
    assert (specials / "link.png").is_symlink() and (specials / "real.png").read_bytes() == b"old"
    (specials / "dangling.png").symlink_to(specials / "nowhere.png")
    with pytest.raises(LeafsimError, match="it is a broken symbolic link"):
        fileio.atomic_write_bytes(specials / "dangling.png", b"new")
    assert not (specials / "nowhere.png").exists()
    # nor is a read-only file replaced (os.replace needs only the folder's permission)
    ro = specials / "ro.png"
    ro.write_bytes(b"keep")
    ro.chmod(0o444)
    with pytest.raises(LeafsimError, match="the file is read-only"):
        fileio.atomic_write_bytes(ro, b"new")
    assert ro.read_bytes() == b"keep" and (ro.stat().st_mode & 0o777) == 0o444
    # leafsim replaces its own files whatever the umask (a checkpoint written again)
    old_mask = os.umask(0o277)
    try:
        fileio.atomic_write_bytes(specials / "own.png", b"one")
        fileio.atomic_write_bytes(specials / "own.png", b"two")
    finally:
        os.umask(old_mask)
    assert (specials / "own.png").read_bytes() == b"two"
    # a folder on the way may be a link
    (specials / "sub").mkdir()
    (specials / "via").symlink_to(specials / "sub")
    fileio.atomic_write_bytes(specials / "via" / "x.png", b"new")
    assert (specials / "sub" / "x.png").read_bytes() == b"new"
    assert not list(specials.glob(".*.tmp"))


@pytest.mark.skipif(os.geteuid() != 0, reason="making a device node needs root")
def test_a_device_is_never_replaced(tmp_path):
    dev = tmp_path / "null.png"
    os.mknod(dev, 0o666 | 0o020000, os.makedev(1, 3))  # a character device like /dev/null
    with pytest.raises(LeafsimError, match="character device"):
        fileio.write_png_atomic(dev, np.zeros((4, 4, 3), np.uint8))
    assert os.path.exists(dev) and not dev.is_file()


def test_outputs_are_checked_before_any_work(specials):
    assert fileio.check_output(specials / "new.png") == specials / "new.png"
    with pytest.raises(LeafsimError, match="named pipe"):
        fileio.check_output(specials / "pipe.png")
    with pytest.raises(LeafsimError, match="does not exist"):
        fileio.check_output(specials / "missing" / "x.png")
    if os.path.isdir("/proc"):
        with pytest.raises(LeafsimError, match="cannot create a file in /proc"):
            fileio.check_output("/proc/leafsim_probe.png")
    with pytest.raises(LeafsimError, match="MiB free"):
        fileio.check_output(specials / "new.png", need_bytes=2**62)
    with pytest.raises(LeafsimError, match="exists and is not a folder"):
        fileio.check_output(specials / "real.png", folder=True)


def test_inputs_must_be_bounded_regular_files(specials, monkeypatch):
    with pytest.raises(LeafsimError, match="named pipe, expected a regular file"):
        fileio.read_json(specials / "pipe.png", "species config")  # would block for ever
    if os.path.exists("/dev/zero"):
        with pytest.raises(LeafsimError, match="character device"):
            fileio.read_json("/dev/zero", "species config")  # would never end
    with pytest.raises(LeafsimError, match="loop of symbolic links"):
        fileio.read_json(specials / "loop_a", "scene file")
    big = specials / "big.json"
    big.write_text(json.dumps({"x": "y" * 5000}))
    monkeypatch.setattr(fileio, "MAX_JSON_BYTES", 1000)
    with pytest.raises(LeafsimError, match="more than the 0 MiB leafsim reads"):
        fileio.read_json(big, "scene file", max_bytes=fileio.MAX_JSON_BYTES)


def test_duplicate_json_keys_are_refused(tmp_path):
    p = tmp_path / "s.json"
    p.write_text('{"groups": [{"count": 2, "count": 100000}]}')
    with pytest.raises(LeafsimError, match="duplicate key 'count'"):
        fileio.read_json(p, "scene file")
