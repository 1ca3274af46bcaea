"""Species library: strict loading of ``configs/leaves.json``.

Each entry names a leaf: its photo (or a drawn outline), real length, base/apex, main-vein
targets (explicit or ``"auto"``), the lateral length profile and any parameter values that
differ from the declared defaults.  Errors name the file, the species and the key.

Coordinates given in an entry (``outline.points``, ``targets``) are *leaf-normalised*:
base (petiole junction) at (0, 0), apex at (0, 1); they are scaled by ``length_m``.
Photo coordinates (``base_px``, ``apex_px``) are pixels of the photo.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import read_json
from leafsim.base.geometry import outline_problem, targets_problem
from leafsim.base.resources import default_config, display_path
from leafsim.config.params import PARAMS, ParamSet, flatten, json_typed, show_json
from leafsim.config.params import show as _show

DEFAULT_SPECIES = "maple"

_ENTRY_KEYS = {
    "name", "latin", "description", "image", "length_m", "base_px", "apex_px",
    "outline", "targets", "main_origin", "lateral_profile", "params", "photo_note", "photo_stage", "senescent_photo",
    "variants",
}
#: what a variant may change (the leaf's shape and photo are its species')
_VARIANT_KEYS = {"name", "latin", "description", "params"}
_REFERENCE_KEYS = {"image", "base_px", "apex_px"}
_OUTLINE_KEYS = {"points", "smooth", "teeth"}
_TEETH_KEYS = {"count", "depth", "skip_base"}


@dataclass(frozen=True)
class Reference:
    """A photo of the species to compare with (``senescent_photo``): the file and, optionally,
    its base and apex in photo pixels (else they are found by the tracer)."""

    image: Path
    base_px: tuple[float, float] | None = None
    apex_px: tuple[float, float] | None = None


@dataclass(frozen=True)
class Species:
    """One validated species entry."""

    key: str
    name: str
    latin: str
    length_m: float
    image: Path | None
    base_px: tuple[float, float] | None
    apex_px: tuple[float, float] | None
    outline_points: np.ndarray | None  # (n, 2) leaf-normalised, None when from photo
    outline_smooth: int
    teeth: dict | None
    targets: np.ndarray | None  # (k, 2) leaf-normalised, None = auto
    main_origin: str  # "base" (palmate) or "midrib" (pinnate lobes)
    lateral_profile: np.ndarray  # (k, 2): position along the vein in % -> length factor
    params: ParamSet
    description: str = ""
    overrides: dict = field(default_factory=dict)
    config: Path | None = None  # the config file the entry came from (for error messages)
    photo_stage: str = "young"  # what the photo shows: "young" (its colour is the young colour) or "senescent"
    senescent: "Reference | None" = None  # a photo of a senescent leaf of the species (compare's reference)

    def error(self, key: str | None, msg: str) -> LeafsimError:
        """A one-line error naming this entry's config file, the species and ``key``."""
        return _err(self.config or Path("(config)"), self.key, key, msg)

    @property
    def has_photo(self) -> bool:
        return self.image is not None

    @property
    def photo_colour(self) -> bool:
        """The photo shows the young leaf: its colour is the young leaf's colour."""
        return self.image is not None and self.photo_stage == "young"

    def summary(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "name": self.name,
            "latin": self.latin,
            "length_m": self.length_m,
            "photo": display_path(self.image) if self.image else None,
            "targets": "auto" if self.targets is None else len(self.targets),
            "main_origin": self.main_origin,
            "overrides": len(self.overrides),
            "photo_stage": self.photo_stage if self.image is not None else None,
            "senescent_photo": _rel(self.senescent.image) if self.senescent is not None else None,
        }


def _rel(p: Path) -> str:
    return display_path(p)


def _err(path: Path, species: str | None, key: str | None, msg: str) -> LeafsimError:
    where = str(path)
    if species is not None:
        where += f": species '{species}'"
    if key is not None:
        where += f", key '{key}'"
    return LeafsimError(f"{where}: {msg}")


#: the most points a drawn outline or a target list may hold (the outline is resampled to
#: ``outline.points`` anyway; a million-point outline took minutes to validate)
MAX_POINTS = 20_000


def _points(path, sp, key, value, min_len=1) -> np.ndarray:
    if isinstance(value, list) and len(value) > MAX_POINTS:
        raise _err(path, sp, key, f"{len(value):,} points, expected at most {MAX_POINTS:,} (it is resampled to "
                                  "outline.points anyway)")
    if isinstance(value, list):  # "0.3" or true in a pair were read as numbers by numpy
        for i, pair in enumerate(value):
            if isinstance(pair, list) and any(isinstance(v, (str, bool)) for v in pair):
                raise _err(path, sp, key, f"pair {i + 1} is {show_json(pair)}: expected [x, y] as JSON numbers, not "
                                          "strings or true/false")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise _err(path, sp, key, "expected a list of [x, y] pairs of finite numbers") from None
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < min_len or not np.isfinite(arr).all():
        raise _err(path, sp, key, f"expected a list of at least {min_len} [x, y] number pairs")
    return arr


def _pair(path, sp, key, value):
    if value is None or value == "auto":
        return None
    arr = _points(path, sp, key, [value])
    return (float(arr[0, 0]), float(arr[0, 1]))


class UnknownSpecies(LeafsimError, KeyError):
    """A species key that is not in the library (a LeafsimError, and a KeyError for code that
    looks keys up in a dict); its text is the one line, not a quoted key."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def _unknown(name, known, where: str = "") -> UnknownSpecies:
    import difflib

    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6) if isinstance(name, str) and name else []
    hint = f"did you mean '{close[0]}'? " if close else ""
    what = "no species given" if not name else f"unknown species {_show(name)}{where}"
    return UnknownSpecies(f"{what} ({hint}known: {', '.join(sorted(known))})")


class Library(dict):
    """The species of a config, by key (:func:`load_library`): a dict whose unknown key is one
    line naming the file, the known keys and the closest one (:class:`UnknownSpecies`), not a
    bare ``KeyError: 'birch'``."""

    def __init__(self, entries, path: Path):
        super().__init__(entries)
        self.path = path

    def __missing__(self, key):
        raise _unknown(key, self, f" in {self.path}")


def load_library(path: str | Path | None = None) -> Library:
    """Load and validate every species of a config file (a :class:`Library`: a dict by key)."""
    if path is not None and not isinstance(path, (str, os.PathLike)):
        raise LeafsimError(f"species config {path!r}: expected a file path (str or Path)")
    path = Path(path) if path is not None else default_config()
    data = read_json(path, "species config")
    if not isinstance(data, dict) or not isinstance(data.get("species"), dict) or not data["species"]:
        raise LeafsimError(f"{path}: expected an object with a non-empty 'species' object")
    stray = [k for k in data if k != "species" and not str(k).startswith("_")]
    if stray:  # e.g. a species entry pasted at the top level, which would be silently ignored
        raise LeafsimError(f"{path}: unknown top-level key {_show(stray[0])} (a config holds \"species\": {{...}} and "
                           "\"_comment\" keys; a species entry goes inside \"species\")")
    entries = {}
    for k, v in data["species"].items():
        for name, entry in [(k, v), *_variants(path, k, v).items()]:
            if name in entries or (name != k and name in data["species"]):
                raise _err(path, k, "variants" if name != k else None, f"species key {_show(name)} is defined twice")
            entries[name] = entry
    return Library({_check_key(path, k): _parse_entry(path, k, v) for k, v in entries.items()}, path)


def _variants(path: Path, key: str, e: Any) -> dict:
    """The entries a species' ``variants`` stand for: ``{"red": {"name": ..., "params": {...}}}``
    becomes the species ``<key>_red``, the entry with that name, latin name and description and
    its parameters over the entry's (e.g. a grapevine's white and red cultivars)."""
    if not isinstance(e, dict) or "variants" not in e:
        return {}
    vs = e["variants"]
    if not isinstance(vs, dict) or not vs:
        raise _err(path, key, "variants", "expected an object of named variants, e.g. {\"red\": {\"params\": {...}}}")
    out = {}
    for name, v in vs.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise _err(path, key, "variants", f"variant name {_show(name)}: expected a word (letters, digits, _)")
        if not isinstance(v, dict) or set(v) - _VARIANT_KEYS:
            bad = sorted(set(v) - _VARIANT_KEYS)[0] if isinstance(v, dict) else None
            raise _err(path, key, f"variants.{name}" + (f".{bad}" if bad else ""),
                       f"expected an object with some of {', '.join(sorted(_VARIANT_KEYS))}")
        params = v.get("params", {})
        if not isinstance(params, dict):
            raise _err(path, key, f"variants.{name}.params", "expected an object of parameter values")
        if not isinstance(e.get("params", {}), dict):
            raise _err(path, key, "params", "expected an object of parameter values")
        base = {k: x for k, x in e.items() if k != "variants"}
        out[f"{key}_{name}"] = {**base, **{k: x for k, x in v.items() if k != "params"},
                                "params": {**e.get("params", {}), **params}}
    return out


def _encodable(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _check_key(path: Path, key: str) -> str:
    """Species keys are printable names (they appear in messages and on the command line)."""
    if not key or not key.isprintable() or key != key.strip():
        raise LeafsimError(f"{path}: species key {_show(key)}: expected a printable name without control characters "
                           "or surrounding spaces")
    return key


def _parse_entry(path: Path, key: str, e: Any) -> Species:
    if not isinstance(e, dict):
        raise _err(path, key, None, "expected an object")
    unknown = set(e) - _ENTRY_KEYS
    if unknown:
        raise _err(path, key, sorted(unknown)[0], f"unknown key (expected one of {', '.join(sorted(_ENTRY_KEYS))})")
    length = e.get("length_m")
    if isinstance(length, bool) or not isinstance(length, (int, float)) or not (0.005 <= length <= 2.0):
        raise _err(path, key, "length_m", f"expected the real leaf length in metres in [0.005, 2], got {_show(length)}")
    for k in ("name", "latin", "description", "photo_note"):
        if k in e and not isinstance(e[k], str):
            raise _err(path, key, k, f"expected a text string, got {_show(e[k])}")
        if k in e and not _encodable(e[k]):  # a lone surrogate ("\ud800") could not be printed: an internal error
            raise _err(path, key, k, "expected text that UTF-8 can write (it holds a lone surrogate code point)")
        if k in ("name", "latin") and k in e and not e[k].isprintable():  # a row of the species table
            raise _err(path, key, k, f"expected one line of printable text, got {_show(e[k])}")

    image = _image(path, key, "image", e["image"]) if e.get("image") is not None else None
    stage = e.get("photo_stage", "young")
    if stage not in ("young", "senescent"):
        raise _err(path, key, "photo_stage", f"expected 'young' or 'senescent' (what the photo shows), got {_show(stage)}")
    senescent = _reference(path, key, e["senescent_photo"]) if e.get("senescent_photo") is not None else None
    base_px, apex_px = _pair(path, key, "base_px", e.get("base_px")), _pair(path, key, "apex_px", e.get("apex_px"))
    if senescent is not None and image is not None and senescent.image == image:
        # the same photo is traced once, with the entry's base and apex: different ones would be ignored
        for k, mine in (("base_px", base_px), ("apex_px", apex_px)):
            theirs = getattr(senescent, k)
            if theirs is not None and (mine is None or not np.allclose(np.asarray(mine, float), theirs)):
                raise _err(path, key, f"senescent_photo.{k}", f"{tuple(float(v) for v in theirs)} differs from the entry's "
                           f"{k} {None if mine is None else tuple(float(v) for v in mine)} for the same photo (expected the same point, or none)")

    outline_pts, smooth, teeth = _outline(path, key, e["outline"]) if "outline" in e else (None, 0, None)
    if image is None and outline_pts is None:
        raise _err(path, key, None, "needs either 'image' (a photo) or 'outline' (drawn points)")
    if image is not None and outline_pts is not None:  # the outline was checked, then ignored for the photo's
        raise _err(path, key, "outline", "and 'image' both give the leaf's outline: expected one of them")

    targets = e.get("targets", "auto")
    targets = None if targets == "auto" else _points(path, key, "targets", targets, 1)
    if targets is not None and outline_pts is not None:
        problem = targets_problem(targets, outline_pts, 1.0)
        if problem:
            raise _err(path, key, "targets", problem)
    origin = e.get("main_origin", "base")
    if origin not in ("base", "midrib"):
        raise _err(path, key, "main_origin", f"expected 'base' or 'midrib', got {origin!r}")
    prof = _points(path, key, "lateral_profile", e.get("lateral_profile", [[0, 1], [100, 1]]), 2)
    if (np.diff(prof[:, 0]) <= 0).any() or prof[0, 0] < 0 or prof[-1, 0] > 100 or (prof[:, 1] < 0).any() or (prof[:, 1] > 1.5).any():
        raise _err(path, key, "lateral_profile", "expected [percent, factor] pairs with increasing percent in 0–100 and factor in 0–1.5")
    overrides = e.get("params", {})
    if not isinstance(overrides, dict):
        raise _err(path, key, "params", "expected an object of parameter values")
    where = f"{path}: species '{key}'"
    for name in flatten(overrides) if isinstance(overrides, dict) else ():
        head, _, tail = name.partition(".")
        if name not in PARAMS and ((head == "outline" and tail in _OUTLINE_KEYS) or name in _ENTRY_KEYS):
            raise _err(path, key, f"params.{name}", f"not a parameter but a key of the species entry's "
                       f"{repr(head) + ' object' if tail else 'own'} (write it there, not inside 'params'; "
                       f"`leafsim params` lists the parameters)")
    params = ParamSet(json_typed(overrides, where), where=where)
    return Species(
        key=key,
        name=str(e.get("name", key)),
        latin=str(e.get("latin", "")),
        length_m=float(length),
        image=image,
        base_px=base_px,
        apex_px=apex_px,
        outline_points=outline_pts,
        outline_smooth=smooth,
        teeth=teeth,
        targets=targets,
        main_origin=origin,
        lateral_profile=prof,
        params=params,
        description=str(e.get("description", "")),
        overrides=dict(overrides),
        config=path,
        photo_stage=stage,
        senescent=senescent,
    )


def _image(path: Path, key: str, name: str, value: Any) -> Path:
    """A photo path of an entry (relative to the config's project), checked to exist."""
    if not isinstance(value, str) or not value.strip():
        raise _err(path, key, name, "expected a path string relative to the config's project"
                   + (", not an empty one" if isinstance(value, str) else ""))
    image = Path(value)
    if not image.is_absolute():
        folder = path.absolute().parent  # as typed, `leaves.json` or `./x.json` has no folder name to test
        base_dir = folder.parent if folder.name == "configs" else folder
        image = (base_dir / image).resolve()
    if image.is_dir():
        raise _err(path, key, name, f"photo {image} is a folder, expected an image file")
    if image.exists() and not image.is_file():
        raise _err(path, key, name, f"photo {image} is not a regular file (a device or a pipe), expected an image file")
    if not image.is_file() and not Path(value).is_absolute():
        # a copy of the shipped library elsewhere still finds the shipped photos (an artist copies
        # leaves.json to tweak one species, and every photo entry of the copy was refused)
        from leafsim.base.resources import data_root

        shipped = (data_root() / value).resolve()
        if shipped.is_file():
            mine = base_dir / Path(value).parts[0]
            if len(Path(value).parts) > 1 and mine.is_dir() and mine.resolve() != (data_root() / Path(value).parts[0]).resolve():
                # the user keeps photos in that folder, yet not this one (a typo?): say which file is read
                import warnings

                from leafsim.base.errors import LeafsimWarning

                warnings.warn(LeafsimWarning(str(_err(path, key, name, f"{value} is not in {mine}; using leafsim's own "
                                                                        f"photo of that name ({shipped})"))), stacklevel=2)
            return shipped
    if not image.is_file():
        where = "" if Path(value).is_absolute() else f" (a relative path is read from {base_dir}, then from leafsim's own data)"
        raise _err(path, key, name, f"photo {image} not found{where}")
    return image


def _reference(path: Path, key: str, value: Any) -> Reference:
    """``senescent_photo``: a path, or an object with ``image`` and optional ``base_px``/``apex_px``."""
    name = "senescent_photo"
    if isinstance(value, str):
        return Reference(_image(path, key, name, value))
    if isinstance(value, dict) and set(value) - _REFERENCE_KEYS:
        raise _err(path, key, f"{name}.{sorted(set(value) - _REFERENCE_KEYS)[0]}",
                   f"unknown key (expected {', '.join(sorted(_REFERENCE_KEYS))})")
    if not isinstance(value, dict) or "image" not in value:
        raise _err(path, key, name, "expected a photo path, or an object with 'image' and optional 'base_px', 'apex_px'")
    return Reference(_image(path, key, f"{name}.image", value["image"]), _pair(path, key, f"{name}.base_px", value.get("base_px")),
                     _pair(path, key, f"{name}.apex_px", value.get("apex_px")))


def _outline(path: Path, key: str, o: Any) -> tuple[np.ndarray, int, dict | None]:
    """Validated drawn ``outline``: (points, smoothing passes, teeth or None)."""
    if not isinstance(o, dict) or "points" not in o:
        raise _err(path, key, "outline", "expected an object with 'points' (leaf-normalised [x, y] pairs)")
    bad = set(o) - _OUTLINE_KEYS
    if bad:
        raise _err(path, key, f"outline.{sorted(bad)[0]}", f"unknown key (expected {', '.join(sorted(_OUTLINE_KEYS))})")
    pts = _points(path, key, "outline.points", o["points"], 3)
    smooth = o.get("smooth", 0)
    if isinstance(smooth, bool) or not isinstance(smooth, int) or not 0 <= smooth <= 6:
        raise _err(path, key, "outline.smooth", "expected an integer 0–6 (Chaikin smoothing passes)")
    problem = outline_problem(pts, (0.0, 0.0), (0.0, 1.0))
    if problem:
        raise _err(path, key, "outline.points", f"the outline {problem}")
    teeth = _teeth(path, key, o["teeth"]) if o.get("teeth") is not None else None
    return pts, smooth, teeth


#: declared ranges of the ``outline.teeth`` keys: (kind, lo, hi, default)
_TEETH = {"count": (int, 0, 400, 0), "depth": (float, 0.0, 0.2, 0.0), "skip_base": (float, 0.0, 1.0, 0.15)}


def _teeth(path: Path, key: str, teeth: Any) -> dict:
    """Validated ``outline.teeth``: count (integer 0–400), depth and skip_base (leaf units)."""
    if isinstance(teeth, dict) and set(teeth) - _TEETH_KEYS:
        raise _err(path, key, f"outline.teeth.{sorted(set(teeth) - _TEETH_KEYS)[0]}",
                   f"unknown key (expected {', '.join(sorted(_TEETH_KEYS))})")
    if not isinstance(teeth, dict):
        raise _err(path, key, "outline.teeth", "expected an object with count, depth and skip_base")
    out = {}
    for name, (kind, lo, hi, default) in _TEETH.items():
        v = teeth.get(name, default)
        ok = not isinstance(v, bool) and isinstance(v, int if kind is int else (int, float)) and lo <= v <= hi
        if not ok:
            what = "an integer" if kind is int else "a number"
            raise _err(path, key, f"outline.teeth.{name}", f"expected {what} in [{lo:g}, {hi:g}], got {_show(v)}")
        out[name] = kind(v)
    return out


def get_species(name: str, path: str | Path | None = None) -> Species:
    """The species ``name`` of the library at ``path`` (default: the built-in one); an unknown
    or empty name is an error that lists the known keys and suggests the closest one."""
    lib = load_library(path)
    if not isinstance(name, str) and name is not None:
        raise LeafsimError(f"species name {name!r}: expected a string (known: {', '.join(sorted(lib))})")
    if name not in lib:
        raise _unknown(name, lib)
    return lib[name]


# ------------------------------------------------------------------ outline of a species


