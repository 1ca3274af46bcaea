"""Where leafsim finds the data it ships: species and quality configs, example scenes, photos
and shaders (``configs/``, ``images/``, ``shaders/``), and the GUI's font.

An installed wheel carries the three top-level folders as package data under
``leafsim/data/`` (the build copies them there, see ``pyproject.toml``); a source checkout
(``pip install -e .``) has them at the top of the repository, where the design card puts
them.  Code asks :func:`data_dir` and never builds such paths from ``__file__`` itself.

User files (a ``--config``, photos it names, outputs) are never looked up here: they resolve
relative to the working directory or to the config file that names them.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from leafsim.base.errors import LeafsimError

#: the shipped data folders
KINDS = ("configs", "images", "shaders")


def _packaged(kind: str) -> Path:
    return Path(str(files("leafsim") / "data" / kind))


def _checkout(kind: str) -> Path:
    return Path(str(files("leafsim"))).resolve().parent / kind


def data_dir(kind: str) -> Path:
    """The folder of shipped data ``kind`` (one of :data:`KINDS`): the wheel's package data, or
    the checkout's top-level folder.  LeafsimError when neither exists (a broken install)."""
    if kind not in KINDS:
        raise ValueError(f"unknown data folder {kind!r}: expected one of {KINDS}")
    for path in (_packaged(kind), _checkout(kind)):
        if path.is_dir():
            return path
    raise LeafsimError(f"leafsim's {kind}/ folder is missing from this installation (looked in {_packaged(kind)} and "
                       f"{_checkout(kind)}); reinstall leafsim")


def data_root() -> Path:
    """The folder that holds ``configs/``, ``images/`` and ``shaders/``."""
    return data_dir("configs").parent


def default_config() -> Path:
    """The built-in species library, ``configs/leaves.json``."""
    return data_dir("configs") / "leaves.json"


def shader_dir() -> Path:
    return data_dir("shaders")


def font_dir() -> Path:
    """The GUI's bundled font (DejaVu Sans and its licence)."""
    return Path(str(files("leafsim") / "gui" / "fonts"))


def display_path(path) -> str:
    """A path as reports show it: relative to the shipped data (``images/quercus_01.png``) or
    to the working directory when it lies inside either, else as given."""
    p = Path(path)
    try:
        r = p.resolve()
    except OSError:
        return str(path)
    for base in (data_root(), Path.cwd().resolve()):
        if r.is_relative_to(base):
            return str(r.relative_to(base))
    return str(path)
