"""What every command shares: one JSON object or text on stdout, the species with its
``--quality`` and ``--set`` values, and ``--effects``."""

from __future__ import annotations

import json
from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output
from leafsim.config.params import PARAMS, ParamSet, parse_set_args
from leafsim.config.presets import quality_overrides
from leafsim.config.species import DEFAULT_SPECIES, Species, get_species


def warn(text: str) -> None:
    """One warning line on stderr (stdout stays the command's result, JSON or text)."""
    import sys

    print(f"leafsim: warning: {' '.join(text.split())}", file=sys.stderr)


def emit(args, obj: dict, text: str) -> None:
    """``--json``: the one JSON object; otherwise the text."""
    if getattr(args, "json", False):
        print(json.dumps(obj, sort_keys=True))
    else:
        print(text)


def overrides(args) -> dict:
    """The quality level's settings (if any), then the --set values (validated)."""
    q = getattr(args, "quality", None)
    return {**(quality_overrides(q) if q else {}), **parse_set_args(args.sets)}


def effects_overrides(spec: str | None) -> dict:
    """``--effects osmosis,shrink,pbd``: the listed effects on, every other one off."""
    if spec is None:
        return {}
    known = sorted(k.split(".", 1)[1] for k in PARAMS if k.startswith("effects."))
    wanted = {e.strip() for e in spec.split(",") if e.strip()}
    bad = wanted - set(known)
    if bad:
        raise LeafsimError(f"--effects: unknown effect '{sorted(bad)[0]}' (expected a comma-separated list of {', '.join(known)})")
    return {f"effects.{e}": e in wanted for e in known}


def species_params(args, effects: bool = False) -> tuple[Species, ParamSet]:
    """The species of ``--species`` (default maple) and its parameters with ``--quality``,
    ``--set`` and (``effects``) ``--effects`` applied."""
    sp = get_species(DEFAULT_SPECIES if args.species is None else args.species, args.config)
    extra = effects_overrides(getattr(args, "effects", None)) if effects else {}
    return sp, sp.params.with_overrides({**overrides(args), **extra}, where="--set")


def png_output(option: str, path: str | None):
    """Check a PNG output before any work (one line naming the option): a ``.png`` name (the
    file holds PNG data, so another suffix would mislabel it), and a writable place that is a
    regular file or nothing."""
    if path is None:
        return None
    if Path(path).suffix.lower() != ".png":
        raise LeafsimError(f"{option} {path}: expected a .png file name (leafsim writes PNG pictures)")
    return check_output(path, f"{option} picture")
