"""Command line: ``leafsim [gui|species|params|outline|veins|build|run|compare|bench|accuracy|scene|export] ...``.

This module only parses: each command is one function of :mod:`leafsim.commands`, called
with the parsed arguments.  Every command prints a one-line error and exits with status 2 on
bad input; ``--json`` prints one JSON object on stdout and nothing else.  The command modules
are imported when their command runs (``leafsim species`` never loads numba or OpenGL).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import re
import shlex
import signal
import sys

from leafsim import __version__
from leafsim.base.errors import LeafsimError
from leafsim.base.signals import Interrupted, main_thread, raise_interrupted
from leafsim.commands import CHECKPOINT, CHECKPOINT_EVERY
from leafsim.config.params import SEED_MAX
from leafsim.config.presets import QUALITY

#: command → "module:function" in leafsim.commands
COMMANDS = {
    "gui": "gui:cmd_gui", "species": "library:cmd_species", "params": "library:cmd_params",
    "outline": "shape:cmd_outline", "veins": "shape:cmd_veins", "build": "shape:cmd_build", "run": "run:cmd_run",
    "compare": "compare:cmd_compare", "bench": "measure:cmd_bench", "accuracy": "measure:cmd_accuracy",
    "scene": "scene:cmd_scene", "export": "export:cmd_export",
}


class _Parser(argparse.ArgumentParser):
    """argparse that raises LeafsimError (one line) instead of printing usage + exiting."""

    def error(self, message):  # noqa: D401
        where = self.prog.removeprefix("leafsim").strip()  # main() adds "leafsim: " once
        raise LeafsimError(f"{where}: {message}" if where else message)


JSON_HELP = "print exactly one JSON object on stdout instead of text (no progress bar)"
CONFIG_HELP = "species config file (default: the shipped configs/leaves.json; see docs/species.md)"


def _int(text: str) -> int:
    """An integer option as ASCII digits (``int()`` also takes ``1_0`` and other scripts' digits)."""
    if not re.fullmatch(r"\s*[+-]?[0-9]{1,30}\s*", text):  # beyond 30 digits nothing is meant
        raise argparse.ArgumentTypeError(f"{text[:24]!r}{'…' if len(text) > 24 else ''}: expected an integer")
    return int(text)


def _seed(text: str) -> int:
    try:
        if not text.strip().isascii() or not text.strip().lstrip("+").isdigit():  # int() takes '1_0' and '٣'
            raise ValueError(text)
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a non-negative integer") from None
    if not 0 <= v <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"{text}: expected a non-negative integer up to 2**63-1")
    return v


def _common(p: argparse.ArgumentParser, seed=True):
    p.add_argument("--species", default=None, help="species key from the config (see `leafsim species`; default "
                   "maple)")
    p.add_argument("--config", default=None, metavar="FILE", help=CONFIG_HELP)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="override a declared parameter, e.g. --set veins.main.kappa=4 (repeatable)")
    if seed:
        p.add_argument("--seed", type=_seed, default=0, help="random seed, a non-negative integer (default 0)")
    p.add_argument("--quality", default=None, choices=tuple(QUALITY),
                   help="mesh and solver settings from the accuracy study's front (see `leafsim params`); --set wins")


def add_stop_options(p: argparse.ArgumentParser, frames_default=None, frames_help="simulate N frames") -> None:
    """``--frames N`` and ``--until dry|water=F|season=S`` (one of them; with both, the run stops
    at whichever comes first)."""
    p.add_argument("--frames", type=_int, default=frames_default, metavar="N", help=frames_help)
    p.add_argument("--until", default=None, metavar="WHEN",
                   help="stop when the leaf is dry (water left ≤ 2 %%, as the GUI's \"Dry to end\"), at water=F "
                        "(a fraction of the fresh leaf's water) or at season=S (the colour clock); with --frames, "
                        "whichever comes first")


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="leafsim", description="Procedural leaves and how they age.")
    ap.add_argument("--version", action="version", version=f"leafsim {__version__}")
    sub = ap.add_subparsers(dest="cmd", parser_class=_Parser)

    _gui_parser(sub)
    _library_parsers(sub)
    _run_parsers(sub)
    _bench_accuracy_parsers(sub)
    _scene_export_parsers(sub)
    return ap


def _gui_parser(sub) -> None:
    """gui: the window, and its scripted runs (screenshots, timing)."""
    g = sub.add_parser("gui", help="interactive application (default)")
    _common(g)
    g.add_argument("--frames", type=_int, default=None, metavar="N",
                   help="simulate to frame N as fast as possible, draw it and exit (scripted screenshots: the "
                        "simulation is bit-identical on any machine, the picture nearly so)")
    g.add_argument("--until", default=None, metavar="dry",
                   help="dry the leaf to the end as fast as possible (the 'Dry to end' button), draw it and exit")
    g.add_argument("--window-frames", type=_int, default=None, metavar="N",
                   help="exit after N window frames drawn with the leaf, playing (timing the window)")
    g.add_argument("--screenshot", default=None, help="save the final window to this PNG (with --frames, --window-frames or --until)")
    g.add_argument("--play", action="store_true", help="start with the simulation playing")


def _library_parsers(sub) -> None:
    """species, params, outline, veins, build: what the library holds and each stage alone."""
    s = sub.add_parser("species", help="list the species library")
    s.add_argument("--config", default=None, metavar="FILE", help=CONFIG_HELP)
    s.add_argument("--json", action="store_true", help=JSON_HELP)

    pr = sub.add_parser("params", help="list every declared parameter")
    pr.add_argument("--json", action="store_true", help=JSON_HELP)
    pr.add_argument("--markdown", action="store_true", help="print the docs/parameters.md table")

    o = sub.add_parser("outline", help="trace a leaf outline from a photo")
    o.add_argument("image", help="a photo of one leaf on a plain background (PNG, JPEG, TIFF, WebP, BMP)")
    o.add_argument("--out", default=None, help="PNG with the traced outline, base, apex and lobe tips")
    o.add_argument("--json", action="store_true", help=JSON_HELP)
    o.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="set a parameter (outline.*, limits.image_pixels; repeatable)")

    v = sub.add_parser("veins", help="grow the venation of a species")
    _common(v)
    v.add_argument("--out", default=None, help="PNG of the veins over the photo / outline")
    v.add_argument("--json", action="store_true", help=JSON_HELP)

    b = sub.add_parser("build", help="build the two-layer blade model")
    _common(b)
    b.add_argument("--json", action="store_true", help=JSON_HELP)


def _run_parsers(sub) -> None:
    """run, compare: a leaf simulated headless, and against its photos."""
    r = sub.add_parser("run", help="simulate headless")
    _common(r)
    add_stop_options(r, frames_help="simulate to frame N (with --resume: to absolute frame N)")
    r.add_argument("--effects", default=None, help="comma-separated effects to enable (others off), e.g. osmosis,shrink,pbd")
    r.add_argument("--stats", default=None, help="write per-frame statistics (JSON lines) here")
    r.add_argument("--out", default=None, help="folder for final positions (.npz) and PNG frames")
    r.add_argument("--every", type=_int, default=0, help="render a PNG frame every K frames into --out")
    r.add_argument("--checkpoint-every", type=_int, default=None, metavar="K",
                   help=f"save the whole state to OUT/{CHECKPOINT} every K frames (default {CHECKPOINT_EVERY} with --out; 0 = never)")
    r.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out (same command otherwise)")
    r.add_argument("--json", action="store_true", help=JSON_HELP)

    cp = sub.add_parser("compare", help="the model top-down beside the species photo (and a senescent one): IoU, margin, veins, colour")
    _common(cp)
    cp.add_argument("--photo", default=None, help="compare with this photo instead of the species photo (base and apex are detected)")
    cp.add_argument("--stage", default=None, help="young, dried (2 %% of the water left) or a frame number; default: young, and "
                                                 "the best-matching stage for a senescent photo named in the config")
    cp.add_argument("--effects", default=None, help="comma-separated effects for the drying run (others off), e.g. osmosis,colour")
    cp.add_argument("--out", default=None, help="montage PNG: photo | model | overlay per row, metrics, colour classes")
    cp.add_argument("--json", action="store_true", help=JSON_HELP)


def _bench_accuracy_parsers(sub) -> None:
    """bench, accuracy: what the kernels cost and what accuracy costs."""
    be = sub.add_parser("bench", help="benchmark the simulation kernels")
    be.add_argument("--json", action="store_true", help=JSON_HELP)
    be.add_argument("--quick", action="store_true", help="small sizes only")
    ac = sub.add_parser("accuracy", help="accuracy against cost: every solver setting against a converged reference")
    ac.add_argument("--species", default="maple", help="species to dry (default maple)")
    ac.add_argument("--config", default=None, metavar="FILE", help=CONFIG_HELP)
    ac.add_argument("--seed", type=_seed, default=0, help="seed of the leaf (default 0)")
    ac.add_argument("--out", default=None, help="folder for accuracy.json, accuracy.md and accuracy_pareto.png")
    ac.add_argument("--quick", action="store_true", help="a coarse, fast-drying leaf and few settings (for tests)")
    ac.add_argument("--floor", type=_int, default=0, metavar="K",
                    help="also dry the default setting K times from start positions perturbed by 1 µm: the "
                         "sensitivity floor below which no error is resolved")
    ac.add_argument("--floor-reference", action="store_true", help="measure the floor on the reference too (slow)")
    ac.add_argument("--groups", default=None, metavar="G,G",
                    help="only these sweeps (mesh, iterations, mass, tolerance, dt, relaxation, osmosis, precision, quality; "
                         "integrator, Sun's explicit integrator, runs only when named)")
    ac.add_argument("--limit", action="store_true",
                    help="the mesh-converged limit instead: static equilibria on three meshes, Richardson-extrapolated, "
                         "and every setting's error against it with its CPU seconds per dried leaf")
    ac.add_argument("--cache", default=None, metavar="DIR", help="with --limit: keep every run here and reuse it (resume)")
    ac.add_argument("--json", action="store_true", help=JSON_HELP)


def _scene_export_parsers(sub) -> None:
    sc = sub.add_parser("scene", help="simulate a scene file of many leaves in parallel")
    sc.add_argument("scene", help="scene JSON (see configs/scenes/ and docs/scenes.md)")
    sc.add_argument("--out", default=None, help="output folder (default out/SCENE_NAME)")
    sc.add_argument("--workers", type=_int, default=None, help="local worker processes (default: the CPUs this process may use)")
    sc.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this Dask scheduler, e.g. tcp://host:8786")
    sc.add_argument("--json", action="store_true", help=JSON_HELP)

    ex = sub.add_parser("export", help="simulate one leaf and write it as a mesh (glTF, OBJ, PLY)")
    _common(ex)
    add_stop_options(ex, frames_help="simulate N frames first (default without --until: 0, the fresh leaf)")
    ex.add_argument("--every", type=_int, default=0, help="glTF: a morph-target key frame every K frames (the drying animation)")
    ex.add_argument("--format", default=None, choices=["glb", "gltf", "obj", "ply"], help="default: from the --out suffix")
    ex.add_argument("--out", required=True, help="output file")
    ex.add_argument("--layers", default="shell", choices=["shell", "mid"], help="closed thin shell from both layers, or the mid-surface with thickness")
    ex.add_argument("--veins", action="store_true", help="add the veins as a second mesh")
    ex.add_argument("--texture", default="auto", choices=["auto", "colours", "photo", "baked"],
                    help="baked: the blade's colour as the window draws it (sub-grid mottle, photo detail) in a "
                         "texture, one state (glb, gltf, obj); colours: pigment colours per vertex (animations, PLY); "
                         "photo: the species photo; auto (default): baked for one state, colours for --every or PLY")
    ex.add_argument("--effects", default=None, help="comma-separated effects to enable (others off)")
    ex.add_argument("--json", action="store_true", help=JSON_HELP)


def one_line(text: str) -> str:
    """The contract's last line of defence: a message never spans several lines."""
    return " ".join(text.split("\n")).replace("\r", " ")


def command(name: str):
    """The function that runs command ``name``."""
    module, func = COMMANDS[name].split(":")
    return getattr(importlib.import_module(f"leafsim.commands.{module}"), func)


def _interrupted_json(args, signum: int, what: str) -> None:
    """``--json`` promises exactly one JSON object, an interrupted command's too: the commands
    that print theirs only at the end (export, compare, scene, ...) get this one."""
    from leafsim.commands.common import EMITTED

    if args is None or not getattr(args, "json", False) or EMITTED[0]:
        return
    try:
        print(json.dumps({"command": args.cmd, "interrupted": signal.Signals(signum).name, "message": what},
                         sort_keys=True), flush=True)
    except (BrokenPipeError, ValueError):
        pass


def _error_json(args, message: str, code: int, argv: list[str] | None = None) -> None:
    """``--json`` promises exactly one JSON object, a failed command's too: the error line's
    message and the exit status, unless the command printed its object already.  A command line
    that did not parse (``args`` None) counts ``--json`` among its words."""
    from leafsim.commands.common import EMITTED

    if args is not None:
        wanted, cmd = getattr(args, "json", False), args.cmd
    else:
        wanted = argv is not None and "--json" in argv
        cmd = argv[0] if argv and argv[0] in COMMANDS else None
    if not wanted or EMITTED[0]:
        return
    try:
        print(json.dumps({"command": cmd, "error": message, "exit": code}, sort_keys=True), flush=True)
    except (BrokenPipeError, ValueError):
        pass


def _path_error(e: OSError) -> str:
    """One line for an operating-system error on a file the user named (a name too long for the
    file system, a file where a folder should be, no permission, a full disk)."""
    name = str(e.filename)
    if len(name) > 80:
        name = name[:40] + "…" + name[-30:] + f" ({len(name)} characters)"
    return f"{name}: {e.strerror or type(e).__name__}"


def _show_warnings() -> None:
    """A :class:`LeafsimWarning` (from the library: a base guessed from the shape) as the
    commands' own warnings read: ``leafsim: warning: ...``, one line on stderr."""
    import warnings

    from leafsim.base.errors import LeafsimWarning
    from leafsim.commands.common import warn

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, LeafsimWarning):
            warn(str(message))
        else:
            shown(message, category, filename, lineno, file, line)

    if getattr(warnings.showwarning, "__name__", "") != "show":
        warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help", "--version"):
        argv = ["gui"] + argv
    # SIGTERM ends a command like Ctrl-C does (one line, no traceback), not silently
    old_term = signal.signal(signal.SIGTERM, raise_interrupted) if main_thread() else None
    args = None
    from leafsim.commands.common import EMITTED, RESOLVED

    _show_warnings()
    EMITTED[0] = False  # this command's object not printed yet (main may run many times in one process)
    RESOLVED.clear()  # nor its species (main may run many times in one process)
    try:
        args = build_parser().parse_args(argv)
        args.command_line = shlex.join(argv)
        return command(args.cmd)(args) or 0
    except LeafsimError as e:
        _error_json(args, one_line(str(e)), 2, argv)
        print(f"leafsim: {one_line(str(e))}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Interrupted) as e:
        signum = e.signum if isinstance(e, Interrupted) else signal.SIGINT
        what = e.message if isinstance(e, Interrupted) and e.message else "interrupted"
        _interrupted_json(args, signum, what)
        print(f"leafsim: {what} (by {signal.Signals(signum).name})", file=sys.stderr)
        return 128 + int(signum)
    except BrokenPipeError:
        return 0
    except OSError as e:
        if e.filename is None or os.environ.get("LEAFSIM_DEBUG"):
            return _internal(args, e)
        _error_json(args, one_line(_path_error(e)), 2)
        print(f"leafsim: {one_line(_path_error(e))}", file=sys.stderr)
        return 2
    except Exception as e:  # never a traceback for the user
        return _internal(args, e)
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def _internal(args, e: Exception) -> int:
    """An error leafsim did not foresee: one line (a traceback with LEAFSIM_DEBUG set)."""
    if os.environ.get("LEAFSIM_DEBUG"):
        raise e
    msg = f"internal error: {type(e).__name__}: {one_line(str(e))[:300]}"
    _error_json(args, msg, 1)
    print(f"leafsim: {msg} (set LEAFSIM_DEBUG=1 for a traceback)", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
