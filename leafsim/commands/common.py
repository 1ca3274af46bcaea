"""What every command shares: one JSON object or text on stdout, the species with its
``--quality`` and ``--set`` values, and ``--effects``."""

from __future__ import annotations

import json
import time
from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output, not_an_input
from leafsim.config.params import NUMBER, PARAMS, ParamSet, parse_set_args
from leafsim.config.presets import quality_overrides
from leafsim.config.species import DEFAULT_SPECIES, Species, get_species, load_library
from leafsim.interactive.eta import DryingEta, duration


def warn(text: str) -> None:
    """One warning line on stderr (stdout stays the command's result, JSON or text)."""
    import sys

    print(f"leafsim: warning: {' '.join(text.split())}", file=sys.stderr)


#: whether this process printed its ``--json`` object (an interrupted command prints one then)
EMITTED = [False]


#: what :func:`species_params` resolved for this command (its ``provenance``)
RESOLVED: dict = {}


def emit(args, obj: dict, text: str) -> None:
    """``--json``: the one JSON object, with its ``provenance`` (:mod:`leafsim.base.provenance`:
    version, commit, libraries, and the species, config and every parameter that differs from
    leafsim's declared defaults); otherwise the text."""
    if getattr(args, "json", False):
        if isinstance(obj, dict) and "provenance" not in obj:
            from leafsim.base.provenance import provenance

            obj = {**obj, "provenance": provenance(command=getattr(args, "command_line", None), **RESOLVED)}
        print(json.dumps(obj, sort_keys=True))
        EMITTED[0] = True
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
    if not wanted:  # an empty list would silently switch every effect off
        raise LeafsimError(f"--effects {spec!r}: expected a comma-separated list of {', '.join(known)}")
    bad = wanted - set(known)
    if bad:
        raise LeafsimError(f"--effects: unknown effect '{sorted(bad)[0]}' (expected a comma-separated list of {', '.join(known)})")
    return {f"effects.{e}": e in wanted for e in known}


def ready_kernels() -> None:
    """Before a command's first build or step: compile the kernels now, announced, when this
    leafsim version has not compiled them yet (:mod:`leafsim.interactive.warmup`); at once otherwise."""
    from leafsim.interactive.warmup import warm_up_cli

    warm_up_cli()


def species_params(args, effects: bool = False) -> tuple[Species, ParamSet]:
    """The species of ``--species`` (default maple) and its parameters with ``--quality``,
    ``--set`` and (``effects``) ``--effects`` applied."""
    if args.species is None and args.config is not None:  # the default may not be in the user's file
        lib = load_library(args.config)  # (a file that cannot be read says so itself)
        if DEFAULT_SPECIES not in lib:
            raise LeafsimError(f"no --species given, and the default '{DEFAULT_SPECIES}' is not in --config "
                               f"{args.config}: name one with --species (known: {', '.join(sorted(lib))})")
    sp = get_species(DEFAULT_SPECIES if args.species is None else args.species, args.config)
    extra = effects_overrides(getattr(args, "effects", None)) if effects else {}
    given = overrides(args)
    both = sorted(k for k in parse_set_args(args.sets) if k in extra)
    if both:  # --effects sets every effect: a --set of one would be dropped without a word
        raise LeafsimError(f"--set {both[0]} with --effects {args.effects}: --effects switches every effect on or off; "
                           f"list the effects you want in --effects, or use --set effects.* without it")
    params = sp.params.with_overrides({**given, **extra}, where="--set")
    if effects:  # a command that simulates: substeps coarser than any measured level give a wrong shape, silently
        from leafsim.sim.effects.dynamics import unmeasured_substeps

        coarse = unmeasured_substeps(params)
        if coarse:
            warn(coarse)
    RESOLVED.clear()
    RESOLVED.update(species=sp.key, config=str(sp.config) if sp.config is not None else "(shipped configs/leaves.json)",
                    seed=getattr(args, "seed", None), quality=getattr(args, "quality", None),
                    params=params.changed())  # every value that differs from the declared defaults
    return sp, params


def species_inputs(sp) -> tuple:
    """The files a species' run reads: its config and photos (outputs must not be one of them)."""
    return (sp.config, sp.image, sp.senescent.image if sp.senescent is not None else None)


def png_output(option: str, path: str | None, inputs=()):
    """Check a PNG output before any work (one line naming the option): a ``.png`` name (the
    file holds PNG data, so another suffix would mislabel it), a writable place that is a
    regular file or nothing, and none of the command's ``inputs`` (photos it reads)."""
    if path is None:
        return None
    if Path(path).suffix.lower() != ".png":
        raise LeafsimError(f"{option} {path}: expected a .png file name (leafsim writes PNG pictures)")
    not_an_input(path, inputs, option)
    return check_output(path, f"{option} picture")


def stop_of(args, start: int = 0):
    """The :class:`~leafsim.sim.run.Stop` of ``--frames`` / ``--until`` (one line on a bad value).
    ``--until`` alone may run up to DRY_MAX_FRAMES frames, then fails naming the criterion."""
    from leafsim.sim.run import DRY_END_FRACTION, DRY_MAX_FRAMES, MAX_RUN_FRAMES, Stop

    frames, until = getattr(args, "frames", None), getattr(args, "until", None)
    if frames is not None and not 0 <= frames <= MAX_RUN_FRAMES:
        raise LeafsimError(f"--frames {frames}: expected a number of frames from 0 to {MAX_RUN_FRAMES}")
    if until is None:
        if frames is None:
            raise LeafsimError("give --frames N or --until dry (how long to simulate)")
        return Stop(frames=frames)
    kind, _, value = until.strip().partition("=")
    kind = kind.strip().lower()
    if kind == "dry" and not value:
        water, season = DRY_END_FRACTION, None
    elif kind in ("water", "season") and value:
        try:
            v = float(value) if NUMBER.fullmatch(value.strip()) else float("nan")  # not '0.9_9', not '٠.٥'
        except ValueError:
            v = float("nan")
        if not (v == v and (0.0 <= v <= 1.0 if kind == "water" else 0.0 <= v <= 10.0)):
            raise LeafsimError(f"--until {until}: expected " + ("water=F with F in [0, 1] (a fraction of the fresh water)"
                                                                 if kind == "water" else "season=S with S in [0, 10] (the season clock)"))
        water, season = (v, None) if kind == "water" else (None, v)
    else:
        raise LeafsimError(f"--until {until!r}: expected dry, water=F or season=S")
    return Stop(frames=frames, water_left=water, season=season,
                max_frames=None if frames is not None else start + DRY_MAX_FRAMES)


class Progress:
    """A progress bar on stderr (tqdm) while a leaf runs toward its :class:`Stop`, shown only
    on a terminal and never with ``--json``.  (A first run of a version compiles the kernels
    before the bar: :func:`ready_kernels`.)"""

    def __init__(self, args, run, stop, desc: str):
        import sys

        self.run, self.stop, self.start = run, stop, run.state.frame
        self.bar = self.eta = None
        if sys.stderr.isatty() and not getattr(args, "json", False):
            from tqdm import tqdm

            # a drying says its own time left (tqdm's recent rate runs short once the drying slows)
            if stop.water_left is not None and stop.frames is None and stop.season is None:
                self.eta = DryingEta(stop.water_left)
                self.eta.start(time.monotonic(), stop.progress(run, self.start))
            left = "" if self.eta is not None else "<{remaining}"
            self.bar = tqdm(total=1000, desc=f"{desc}: first frame",
                            file=sys.stderr, bar_format="{desc} {percentage:3.0f}%|{bar}| {elapsed}" + left + "{postfix}",
                            leave=False)
            self.desc = desc
        self._first = True

    def update(self) -> None:
        if self.bar is None:
            return
        if self._first:
            self.bar.set_description_str(self.desc, refresh=False)
            self._first = False
        progress = self.stop.progress(self.run, self.start)
        done = int(round(1000 * progress))
        if done > self.bar.n:
            self.bar.update(done - self.bar.n)
        s = self.run.state
        text = f"frame {s.frame}, water {100 * self.run.water_left:.0f} %"
        if self.eta is not None:
            now = time.monotonic()
            self.eta.frame(now, self.run.water_left, self.run.sim.on_coarsest)
            left = self.eta.left(now, progress)
            text += "" if left is None else f", {duration(left)} left"
        self.bar.set_postfix_str(text, refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
