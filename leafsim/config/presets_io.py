"""Parameter sets as files: species, seed and every parameter value, the format the GUI's
"Save params" writes and "Load params" reads (``leafsim-params/1``).

>>> write_param_set("my.json", "oak", 3, params)            # doctest: +SKIP
>>> species, seed, params = read_param_set("my.json", "oak", 3)   # doctest: +SKIP
"""

from __future__ import annotations

import json
from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import atomic_write_bytes, read_json
from leafsim.config.params import PARAMS, ParamSet, check_seed, flatten, json_typed, unknown_key_message
from leafsim.config.species import get_species

#: file format tag of saved parameter sets
PRESET_FORMAT = "leafsim-params/1"
PRESET_KEYS = {"format", "species", "seed", "params"}


def write_param_set(path, species: str, seed: int, params: ParamSet) -> Path:
    """Write species, seed and every parameter value as JSON (atomically)."""
    doc = {"format": PRESET_FORMAT, "species": species, "seed": seed, "params": params.to_dict()}
    return atomic_write_bytes(path, (json.dumps(doc, indent=1, sort_keys=True) + "\n").encode())


def _read_json(path: Path):
    doc = read_json(path, "parameter file")
    if not isinstance(doc, dict):
        raise LeafsimError(f"{path}: expected a JSON object of parameter values")
    return doc


def _header(path: Path, doc: dict, species: str, seed: int) -> tuple[dict, str, int]:
    """(values, species, seed) of a ``{"format", "species", "seed", "params"}`` document."""
    bad = sorted(set(doc) - PRESET_KEYS)
    if bad:
        raise LeafsimError(f"{path}: unknown key '{bad[0]}' (expected {', '.join(sorted(PRESET_KEYS))})")
    fmt = doc.get("format", PRESET_FORMAT)
    if fmt != PRESET_FORMAT:  # another tool's file, or a later version's: its keys may mean other things
        shown = repr(fmt) if len(repr(fmt)) <= 40 else repr(fmt)[:36] + "…"
        raise LeafsimError(f"{path}: 'format' is {shown}: expected {PRESET_FORMAT!r} (a parameter set saved by leafsim)")
    values = doc["params"]
    if not isinstance(values, dict):
        raise LeafsimError(f"{path}: 'params' must be an object of parameter values")
    species = doc.get("species", species)
    seed = doc.get("seed", seed)
    if not isinstance(species, str):
        raise LeafsimError(f"{path}: 'species' must be a species key string")
    return values, species, check_seed(seed, str(path))


def read_param_set(path, species: str, seed: int, config=None, species_params: ParamSet | None = None
                   ) -> tuple[str, int, ParamSet]:
    """Parse and validate a parameter-set JSON: (species, seed, params).

    Accepts what :func:`write_param_set` writes (every key optional but ``params``) or a plain
    object of dotted values.  ``species``/``seed`` are the current ones (used when the file
    names none); missing values come from the file's species (``species_params`` for the
    current species, else loaded from ``config``).  Raises LeafsimError naming the file.
    """
    path = Path(path)
    doc = _read_json(path)
    if "params" in doc:
        values, file_species, seed = _header(path, doc, species, seed)
    else:
        values, file_species = doc, species
    for k in flatten(values):
        if k not in PARAMS:
            raise LeafsimError(unknown_key_message(k, str(path)))
    if file_species == species and species_params is not None:
        base = species_params
    else:
        base = get_species(file_species, config).params
    return file_species, int(seed), base.with_overrides(json_typed(values, str(path)), where=str(path))
