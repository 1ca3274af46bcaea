"""Command line: ``leafsim [gui|species|params|outline|veins|build|run|compare|bench|scene|export] ...``.

Every command prints a one-line error and exits with status 2 on bad input; ``--json``
prints one JSON object on stdout and nothing else.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from pathlib import Path

from .errors import LeafsimError

#: the checkpoint file of ``leafsim run`` inside --out, and how often it is written by default
CHECKPOINT = "checkpoint.npz"
CHECKPOINT_EVERY = 100


class _Parser(argparse.ArgumentParser):
    """argparse that raises LeafsimError (one line) instead of printing usage + exiting."""

    def error(self, message):  # noqa: D401
        raise LeafsimError(f"{self.prog}: {message}")


#: seeds are non-negative integers below 2**63 (numpy's generators take them as-is)
SEED_MAX = 2**63 - 1


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a non-negative integer") from None
    if not 0 <= v <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"{text}: expected a non-negative integer up to 2**63-1")
    return v


def _common(p: argparse.ArgumentParser, seed=True):
    p.add_argument("--species", default=None, help="species key from the config (see `leafsim species`)")
    p.add_argument("--config", default=None, help="species config JSON (default: configs/leaves.json)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="override a declared parameter, e.g. --set veins.main.kappa=4 (repeatable)")
    if seed:
        p.add_argument("--seed", type=_seed, default=0, help="random seed, a non-negative integer (default 0)")
    from .sim.presets import QUALITY

    p.add_argument("--quality", default=None, choices=tuple(QUALITY),
                   help="mesh and solver settings from the accuracy study's front (see `leafsim params`); --set wins")


def _overrides(args) -> dict:
    """The quality level's settings (if any), then the --set values (validated)."""
    from .params import parse_set_args
    from .sim.presets import quality_overrides

    q = getattr(args, "quality", None)
    return {**(quality_overrides(q) if q else {}), **parse_set_args(args.sets)}


def build_parser() -> argparse.ArgumentParser:
    ap = _Parser(prog="leafsim", description="Procedural leaves and how they age.")
    sub = ap.add_subparsers(dest="cmd", parser_class=_Parser)

    g = sub.add_parser("gui", help="interactive application (default)")
    _common(g)
    g.add_argument("--frames", type=int, default=None, help="run N frames then exit (scripted checks)")
    g.add_argument("--screenshot", default=None, help="save the final window to this PNG (with --frames)")
    g.add_argument("--play", action="store_true", help="start with the simulation playing")

    s = sub.add_parser("species", help="list the species library")
    s.add_argument("--config", default=None)
    s.add_argument("--json", action="store_true")

    pr = sub.add_parser("params", help="list every declared parameter")
    pr.add_argument("--json", action="store_true")
    pr.add_argument("--markdown", action="store_true", help="print the docs/parameters.md table")

    o = sub.add_parser("outline", help="trace a leaf outline from a photo")
    o.add_argument("image")
    o.add_argument("--out", default=None, help="PNG with the traced outline, base, apex and lobe tips")
    o.add_argument("--json", action="store_true")
    o.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")

    v = sub.add_parser("veins", help="grow the venation of a species")
    _common(v)
    v.add_argument("--out", default=None, help="PNG of the veins over the photo / outline")
    v.add_argument("--json", action="store_true")

    b = sub.add_parser("build", help="build the two-layer blade model")
    _common(b)
    b.add_argument("--json", action="store_true")

    r = sub.add_parser("run", help="simulate headless")
    _common(r)
    r.add_argument("--frames", type=int, required=True)
    r.add_argument("--effects", default=None, help="comma-separated effects to enable (others off), e.g. osmosis,shrink,pbd")
    r.add_argument("--stats", default=None, help="write per-frame statistics (JSON lines) here")
    r.add_argument("--out", default=None, help="folder for final positions (.npz) and PNG frames")
    r.add_argument("--every", type=int, default=0, help="render a PNG frame every K frames into --out")
    r.add_argument("--checkpoint-every", type=int, default=None, metavar="K",
                   help=f"save the whole state to OUT/{CHECKPOINT} every K frames (default {CHECKPOINT_EVERY} with --out; 0 = never)")
    r.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out (same command otherwise)")
    r.add_argument("--json", action="store_true")

    cp = sub.add_parser("compare", help="the model top-down beside the species photo (and a senescent one): IoU, margin, veins, colour")
    _common(cp)
    cp.add_argument("--photo", default=None, help="compare with this photo instead of the species photo (base and apex are detected)")
    cp.add_argument("--stage", default=None, help="young, dried (2 %% of the water left) or a frame number; default: young, and "
                                                 "the best-matching stage for a senescent photo named in the config")
    cp.add_argument("--effects", default=None, help="comma-separated effects for the drying run (others off), e.g. osmosis,colour")
    cp.add_argument("--out", default=None, help="montage PNG: photo | model | overlay per row, metrics, colour classes")
    cp.add_argument("--json", action="store_true")

    be = sub.add_parser("bench", help="benchmark the simulation kernels")
    be.add_argument("--json", action="store_true")
    be.add_argument("--quick", action="store_true", help="small sizes only")
    ac = sub.add_parser("accuracy", help="accuracy against cost: every solver setting against a converged reference")
    ac.add_argument("--species", default="maple", help="species to dry (default maple)")
    ac.add_argument("--config", default=None)
    ac.add_argument("--seed", type=int, default=0)
    ac.add_argument("--out", default=None, help="folder for accuracy.json, accuracy.md and accuracy_pareto.png")
    ac.add_argument("--quick", action="store_true", help="a coarse, fast-drying leaf and few settings (for tests)")
    ac.add_argument("--floor", type=int, default=0, metavar="K",
                    help="also dry the default setting K times from start positions perturbed by 1 µm: the "
                         "sensitivity floor below which no error is resolved")
    ac.add_argument("--floor-reference", action="store_true", help="measure the floor on the reference too (slow)")
    ac.add_argument("--groups", default=None, metavar="G,G",
                    help="only these sweeps (mesh, iterations, mass, tolerance, dt, relaxation, osmosis, precision, quality)")
    ac.add_argument("--json", action="store_true")
    _scene_export_parsers(sub)
    return ap


class Interrupted(BaseException):
    """SIGINT or SIGTERM ended a command: the CLI prints one line and exits with 128 + signal.
    A BaseException (like KeyboardInterrupt), so no ``except Exception`` swallows it."""

    def __init__(self, signum: int, message: str = ""):
        super().__init__(signum, message)
        self.signum, self.message = signum, message


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        argv = ["gui"] + argv
    # SIGTERM ends a command like Ctrl-C does (one line, no traceback), not silently
    old_term = signal.signal(signal.SIGTERM, _raise_interrupted) if _main_thread() else None
    try:
        args = build_parser().parse_args(argv)
        return COMMANDS[args.cmd](args) or 0
    except LeafsimError as e:
        print(f"leafsim: {one_line(str(e))}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, Interrupted) as e:
        signum = e.signum if isinstance(e, Interrupted) else signal.SIGINT
        what = e.message if isinstance(e, Interrupted) and e.message else "interrupted"
        print(f"leafsim: {what} (by {signal.Signals(signum).name})", file=sys.stderr)
        return 128 + int(signum)
    except BrokenPipeError:
        return 0
    except Exception as e:  # never a traceback for the user
        if os.environ.get("LEAFSIM_DEBUG"):
            raise
        print(f"leafsim: internal error: {type(e).__name__}: {one_line(str(e))[:300]} (set LEAFSIM_DEBUG=1 for a traceback)", file=sys.stderr)
        return 1
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


class _DeferredSignals:
    """Inside the frame loop, SIGINT/SIGTERM only set ``signum``: the loop finishes the frame it
    is in, saves a checkpoint and stops, so the state on disk is always a whole frame.  A
    second signal ends at once."""

    def __init__(self):
        self.signum = None

    def _handler(self, signum, frame):
        if self.signum is not None:
            raise Interrupted(signum)
        self.signum = signum

    def __enter__(self):
        self._old = {s: signal.signal(s, self._handler) for s in (signal.SIGINT, signal.SIGTERM)} if _main_thread() else {}
        return self

    def __exit__(self, *exc):
        for s, h in self._old.items():
            signal.signal(s, h)


def one_line(text: str) -> str:
    """The contract's last line of defence: a message never spans several lines."""
    return " ".join(text.split("\n")).replace("\r", " ")


def _emit(args, obj: dict, text: str) -> None:
    if getattr(args, "json", False):
        print(json.dumps(obj, sort_keys=True))
    else:
        print(text)


def _load(args):
    """Species + validated parameters (species values, then --set overrides)."""
    from .species import DEFAULT_SPECIES, get_species

    sp = get_species(args.species or DEFAULT_SPECIES, args.config)
    params = sp.params.with_overrides(_overrides(args), where="--set")
    return sp, params


# ------------------------------------------------------------------ commands

def cmd_species(args):
    from .species import load_library

    lib = load_library(args.config)
    rows = [sp.summary() for sp in lib.values()]
    lines = [f"{'key':16s} {'name':32s} {'length':>7s}  photo"]
    for r in rows:
        lines.append(f"{r['key']:16s} {r['name']:32s} {r['length_m']:6.3f}m  {r['photo'] or '(drawn outline)'}")
    _emit(args, {"species": rows}, "\n".join(lines))


def cmd_params(args):
    from .params import PARAMS, markdown_table

    if args.markdown:
        print(markdown_table())
        return
    from .sim.presets import quality_table

    rows = [{"name": p.name, "kind": p.kind, "default": p.default, "lo": p.lo, "hi": p.hi, "unit": p.unit,
             "group": p.group, "rebuild": p.rebuild, "choices": list(p.choices), "help": p.help} for p in PARAMS.values()]
    text = "\n".join(f"{r['name']:36s} {str(r['default']):>10s} {r['unit']:10s} {'rebuild' if r['rebuild'] else 'live':7s} {r['help']}" for r in rows)
    from .params import ParamSet
    from .sim.presets import quality_of

    quality, default = quality_table(), quality_of(ParamSet())
    text += "\n\n--quality (measured by the accuracy study, docs/accuracy.md; the defaults are " + f"{default}):\n" + "\n".join(
        f"  {k:10s} {json.dumps(v['settings']):60s} " + (_quality_measured(v["measured"]) if v["measured"] else "not measured")
        for k, v in quality.items())
    _emit(args, {"params": rows, "quality": quality}, text)


def _quality_measured(m: dict) -> str:
    return (f"worst error {100 * m['worst_rel']:.0f} % of the reference, {m['ms_per_sim_s']:.0f} ms per simulated second "
            f"({m['particles']} particles, maple)")


def cmd_outline(args):
    from .outline import draw_outline, load_image, outline_report, trace_outline
    from .params import ParamSet, parse_set_args

    params = ParamSet(parse_set_args(args.sets))
    traced = trace_outline(args.image, params)
    rep = outline_report(traced)
    if args.out:
        draw_outline(traced, load_image(args.image), args.out)
    _emit(args, rep, f"{args.image}: {rep['points']} points, area {rep['area_px']:.0f} px, base {rep['base']}, apex {rep['apex']}, "
                     f"{len(rep['lobes'])} lobe tips, IoU {rep['iou']:.4f}" + (f" -> {args.out}" if args.out else ""))


def cmd_veins(args):
    from .draw2d import draw_veins, write_png_atomic
    from .leaf import leaf_shape, species_veins

    sp, params = _load(args)
    t0 = time.perf_counter()
    shape = leaf_shape(sp, params)
    graph = species_veins(sp, shape, params, args.seed)
    dt = time.perf_counter() - t0
    rep = {"species": sp.key, "seed": args.seed, "length_m": sp.length_m, **graph.stats}
    if args.out:
        photo = None
        if sp.image is not None:
            from .outline import load_image

            photo = load_image(sp.image)
        write_png_atomic(args.out, draw_veins(shape, graph, photo=photo))
    c = graph.stats["counts"]
    _emit(args, rep, f"{sp.key} seed {args.seed}: main {c['main']}, lateral {c['lateral']}, sublateral {c['sublateral']}, net {c['net']}; "
                     f"crossings {graph.stats['crossings']}, outside {graph.stats['outside_length']:.3g} m ({dt * 1000:.0f} ms)"
                     + (f" -> {args.out}" if args.out else ""))


def _model(args):
    from .leaf import build_leaf

    sp, params = _load(args)
    shape, graph, model = build_leaf(sp, params, args.seed)
    return sp, params, shape, graph, model


def cmd_build(args):
    sp, params, shape, graph, model = _model(args)
    rep = {"species": sp.key, "seed": args.seed, **model.to_report()}
    _emit(args, rep, json.dumps(rep, indent=1, sort_keys=True))


def _effects_overrides(spec: str | None) -> dict:
    """``--effects osmosis,shrink,pbd``: the listed effects on, every other one off."""
    from .params import PARAMS

    if spec is None:
        return {}
    known = sorted(k.split(".", 1)[1] for k in PARAMS if k.startswith("effects."))
    wanted = {e.strip() for e in spec.split(",") if e.strip()}
    bad = wanted - set(known)
    if bad:
        raise LeafsimError(f"--effects: unknown effect '{sorted(bad)[0]}' (expected a comma-separated list of {', '.join(known)})")
    return {f"effects.{e}": e in wanted for e in known}


def _check_run_args(args) -> Path | None:
    """Validate ``leafsim run``'s options before any work; returns the --out folder (or None)."""
    if args.frames < 0:
        raise LeafsimError(f"--frames {args.frames}: expected a non-negative number of frames")
    if args.every < 0:
        raise LeafsimError(f"--every {args.every}: expected a non-negative frame interval")
    if args.every and not args.out:
        raise LeafsimError("--every needs --out DIR for the PNG frames")
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        raise LeafsimError(f"--checkpoint-every {args.checkpoint_every}: expected a non-negative frame interval")
    if (args.checkpoint_every or args.resume) and not args.out:
        raise LeafsimError(f"{'--resume' if args.resume else '--checkpoint-every'} needs --out DIR (the checkpoint lives there)")
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise LeafsimError(f"--out {out}: exists and is not a folder")
        if not out.parent.exists():
            raise LeafsimError(f"--out {out}: parent folder {out.parent} does not exist")
        if args.resume and not (out / CHECKPOINT).is_file():
            raise LeafsimError(f"--resume: no checkpoint at {out / CHECKPOINT} (run first with --out {out})")
    if args.stats and not Path(args.stats).parent.exists():
        raise LeafsimError(f"--stats {args.stats}: folder {Path(args.stats).parent} does not exist")
    if args.checkpoint_every is None:
        args.checkpoint_every = CHECKPOINT_EVERY if out is not None else 0
    return out


def cmd_run(args):
    from .fileio import remove_stale_temps
    from .leaf import build_leaf, species_photo_rgba
    from .sim.checkpoint import check_meta, load_checkpoint, save_checkpoint
    from .sim.run import StatsStream, run_headless, save_npz
    from .sim.simulator import Simulator
    from .species import DEFAULT_SPECIES, get_species

    out = _check_run_args(args)
    overrides = {**_overrides(args), **_effects_overrides(args.effects)}
    t0 = time.perf_counter()
    sp = get_species(args.species or DEFAULT_SPECIES, args.config)
    params = sp.params.with_overrides(overrides, where="--set")
    # what a checkpoint must have been made with to be resumed by this command
    meta = {"species": sp.key, "config": str(Path(args.config).resolve()) if args.config else None,
            "seed": args.seed, "params": params.to_dict()}
    ck = out / CHECKPOINT if out is not None else None
    if args.resume:
        check_meta(ck, meta)  # before the build: a mismatch costs nothing
    shape, veins, model = build_leaf(sp, params, args.seed)
    build_s = time.perf_counter() - t0
    sim = Simulator(model, params, seed=args.seed)
    state = load_checkpoint(ck, model, meta) if args.resume else sim.state()
    start = state.frame
    snap = None
    if out is not None:
        out.mkdir(exist_ok=True)
    for target in ([ck, out / "final.npz", out / "frame_*.png"] if out is not None else []) + ([Path(args.stats)] if args.stats else []):
        remove_stale_temps(target)  # left by a run killed (SIGKILL) while writing
    if args.every:
        photo = species_photo_rgba(sp, params) if (sp.image is not None and params["render.texture"]) else None
        snap = _FrameWriter(model, params, photo, out, sim.state(), sp.photo_colour)
        if start == 0:
            snap.write(0, state)

    def on_frame(k, state, st):
        if snap is not None and k % args.every == 0:
            snap.write(k, state)
        if ck is not None and args.checkpoint_every and (stop.signum or k % args.checkpoint_every == 0):
            save_checkpoint(ck, model, state, meta)
        return stop.signum is None

    stream = StatsStream(args.stats, keep_until=start if args.resume else None) if args.stats else None
    t1 = time.perf_counter()
    try:
        with _DeferredSignals() as stop:
            state, stats = run_headless(model, params, max(args.frames - start, 0), on_frame=on_frame,
                                        state=state, simulator=sim, stats_stream=stream)
    finally:
        if stream is not None:
            stream.close()
    sim_s = time.perf_counter() - t1
    if stop.signum is not None:
        where = (f"checkpoint {ck}: continue with the same command and --resume" if ck is not None and args.checkpoint_every
                 else "no checkpoint (give --out DIR and --checkpoint-every K to be able to resume)")
        raise Interrupted(stop.signum, f"interrupted at frame {state.frame} of {args.frames}"
                                       + (f", statistics in {args.stats}" if args.stats else "") + f"; {where}")
    if ck is not None and args.checkpoint_every:
        save_checkpoint(ck, model, state, meta)  # the final state: --resume --frames M continues it
    if out is not None:
        save_npz(out / "final.npz", model, state)
    rep = _run_report(sp, params, args, model, state, stats, start, build_s, sim_s, snap)
    _emit(args, rep, json.dumps(rep, indent=1, sort_keys=True))


def _run_report(sp, params, args, model, state, stats, start, build_s, sim_s, snap) -> dict:
    import numpy as np

    from .sim.run import shape_metrics

    ms = [sum(s["ms"].values()) for s in stats]
    water = float(state.particle_water.sum() / max(model.particle_water0.sum(), 1e-300))
    rep = {
        "species": sp.key, "seed": args.seed, "frames": len(stats), "frame": state.frame, "resumed_from": start,
        "build_s": round(build_s, 3), "sim_s": round(sim_s, 3),
        "ms_per_frame_median": round(float(np.median(ms)), 4) if ms else 0.0,
        "water_fraction": round(water, 6),
        "nan": bool(any(s.get("nan") for s in stats)),
        "png_frames": 0 if snap is None else snap.written,
        **{f"shape_{k}": v for k, v in shape_metrics(model, state).items()},
        **model.to_report(),
    }
    if rep["nan"]:
        raise LeafsimError(f"{sp.key}: the simulation produced NaN at frame {state.frame} (parameters: {params.changed()})")
    return rep


class _FrameWriter:
    """Offscreen PNG frames of one leaf (photo species: the pigment colour carrying the photo's
    detail, as the GUI shows it); the camera is fixed by the first frame."""

    def __init__(self, model, params, photo, out: Path, rest_state, photo_colour: bool = False):
        from .view import LeafView

        self.view = LeafView(model, photo, rest_state.pigments.copy(), photo_tint=False, photo_colour=photo_colour)
        self.params, self.out = params, out
        self.rest = rest_state  # the camera frames the rest leaf (the same after --resume)
        self.renderer = self.camera = None
        self.written = 0

    def write(self, k: int, state) -> None:
        from .render.offscreen import OffscreenRenderer, default_camera
        from .render.options import RenderOptions

        opts = RenderOptions(albedo="detail" if self.view.use_texture(self.params) else "colours")
        path = self.out / f"frame_{k:05d}.png"
        if self.renderer is None:
            self.renderer = OffscreenRenderer(960, 720)
            self.camera = default_camera(self.view.mesh(self.rest, self.params).positions)
            self.renderer.render_png(self.view.mesh(state, self.params), path, camera=self.camera, options=opts)
        else:
            self.renderer.render_png(self.view.update(state, self.params), path, camera=self.camera, options=opts)
        self.written += 1


def _stage_arg(text: str | None):
    if text is None or text in ("young", "dried"):
        return text
    try:
        k = int(text)
    except ValueError:
        k = -1
    if k < 0:
        raise LeafsimError(f"--stage {text!r}: expected young, dried or a non-negative frame number")
    return k


def cmd_compare(args):
    from .species import DEFAULT_SPECIES, get_species

    stage = _stage_arg(args.stage)
    if args.photo is not None and not Path(args.photo).is_file():
        raise LeafsimError(f"--photo {args.photo}: file not found")
    if args.out and not Path(args.out).resolve().parent.is_dir():
        raise LeafsimError(f"--out {args.out}: folder {Path(args.out).parent} does not exist")
    sp = get_species(args.species or DEFAULT_SPECIES, args.config)
    params = sp.params.with_overrides({**_overrides(args), **_effects_overrides(args.effects)}, where="--set")
    from .compare import montage
    from .fileio import write_png_atomic
    from .render.compare_run import run_compare

    rep = run_compare(sp, params, seed=args.seed, photo=args.photo, stage=stage)
    rows = rep.pop("_rows")
    if args.out:
        write_png_atomic(args.out, montage(rep, rows), rgb=True)
        rep["montage"] = str(args.out)
    lines = [f"{sp.key}: {'row':9s} {'frame':>6s} {'water':>6s} {'IoU':>7s} {'margin':>7s} {'colourTV':>8s} {'dE':>6s}  reference"]
    for r in rep["rows"]:
        m = "n/a" if r["margin_ratio"] is None else f"{r['margin_ratio']:.3f}"
        lines.append(f"{sp.key}: {r['kind']:9s} {r['stage']['frame']:6d} {r['stage']['water']:6.2f} {r['iou']:7.4f} {m:>7s} "
                     f"{r['colour_tv']:8.3f} {r['mean_delta_e'] or 0:6.1f}  {r['reference']}")
    _emit(args, rep, "\n".join(lines) + (f"\n-> {args.out}" if args.out else ""))


def cmd_accuracy(args):
    from .accuracy import markdown, study, write_report

    out = Path(args.out) if args.out else None
    if out is not None and out.exists() and not out.is_dir():
        raise LeafsimError(f"--out {out}: exists and is not a folder")
    if out is not None and not out.parent.exists():
        raise LeafsimError(f"--out {out}: parent folder {out.parent} does not exist")
    if args.floor < 0:
        raise LeafsimError(f"--floor {args.floor}: expected a count ≥ 0")
    groups = None if args.groups is None else [g.strip() for g in args.groups.split(",") if g.strip()]
    known = {"mesh", "iterations", "mass", "tolerance", "dt", "relaxation", "osmosis", "precision", "quality"}
    if groups is not None and (not groups or set(groups) - known):
        raise LeafsimError(f"--groups {args.groups}: expected a comma list of {', '.join(sorted(known))}")
    report = study(args.species, quick=args.quick, seed=args.seed, config=args.config, progress=not args.json,
                   floor=args.floor, floor_reference=args.floor_reference, groups=groups)
    if out is not None:
        report["files"] = write_report(report, out)
    _emit(args, report, markdown(report))


def cmd_bench(args):
    from .bench import main as bench_main

    return bench_main(json_out=args.json, quick=args.quick)


def cmd_gui(args):

    if args.screenshot and args.frames is None:
        raise LeafsimError("--screenshot needs --frames N")
    overrides = _overrides(args)
    from .gui.app import run_app

    return run_app(species=args.species, config=args.config, seed=args.seed, overrides=overrides,
                   frames=args.frames, screenshot=args.screenshot, play=args.play)


# ------------------------------------------------------------------ scene and export (leafsim/scene.py, leafsim/export.py)

def _scene_export_parsers(sub) -> None:
    sc = sub.add_parser("scene", help="simulate a scene file of many leaves in parallel")
    sc.add_argument("scene", help="scene JSON (see configs/scenes/ and docs/scenes.md)")
    sc.add_argument("--out", default=None, help="output folder (default out/SCENE_NAME)")
    sc.add_argument("--workers", type=int, default=None, help="local worker processes (default: the CPU count)")
    sc.add_argument("--scheduler", default=None, metavar="ADDRESS", help="run on this Dask scheduler, e.g. tcp://host:8786")
    sc.add_argument("--json", action="store_true")

    ex = sub.add_parser("export", help="simulate one leaf and write it as a mesh (glTF, OBJ, PLY)")
    _common(ex)
    ex.add_argument("--frames", type=int, default=0, help="simulate N frames first (default 0: the fresh leaf)")
    ex.add_argument("--every", type=int, default=0, help="glTF: a morph-target key frame every K frames (the drying animation)")
    ex.add_argument("--format", default=None, choices=["glb", "gltf", "obj", "ply"], help="default: from the --out suffix")
    ex.add_argument("--out", required=True, help="output file")
    ex.add_argument("--layers", default="shell", choices=["shell", "mid"], help="closed thin shell from both layers, or the mid-surface with thickness")
    ex.add_argument("--veins", action="store_true", help="add the veins as a second mesh")
    ex.add_argument("--texture", default="colours", choices=["colours", "photo"], help="baked pigment colours or the species photo")
    ex.add_argument("--effects", default=None, help="comma-separated effects to enable (others off)")
    ex.add_argument("--json", action="store_true")


def cmd_scene(args):
    from .scene import load_scene, run_scene

    scene = load_scene(args.scene)
    workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
    out = Path(args.out) if args.out else Path("out") / Path(args.scene).stem
    rep = run_scene(scene, out, workers=workers, scheduler=args.scheduler)
    bad = rep["failed"]
    text = (f"{scene.name}: {rep['ran']} leaves simulated, {rep['skipped']} already done, {len(bad)} failed "
            f"in {rep['total_s']:.1f} s ({rep['leaves_per_s'] or 0:.3g} leaves/s) -> {out}")
    _emit(args, rep, text)
    if bad:
        names = ", ".join(f"{b['name']} ({b['error']})" for b in bad)
        print(f"leafsim: scene {scene.name}: {len(bad)} of {rep['leaves']} leaves failed: {names}", file=sys.stderr)
        return 1
    return 0


def cmd_export(args):
    from .export import export_mesh, format_of
    from .leaf import build_leaf, species_photo_rgba
    from .sim.run import run_headless
    from .sim.simulator import Simulator
    from .species import get_species
    from .view import LeafView

    fmt = format_of(args.out, args.format)
    if args.frames < 0 or args.every < 0:
        raise LeafsimError(f"--frames {args.frames} / --every {args.every}: expected non-negative frame counts")
    if args.every and fmt in ("obj", "ply"):
        raise LeafsimError(f"--every needs --format glb or gltf ({fmt} holds one static shape)")
    folder = Path(args.out).parent
    if not folder.is_dir():
        raise LeafsimError(f"--out {args.out}: folder {folder} does not exist")
    sp = get_species(args.species, args.config)
    params = sp.params.with_overrides({**_overrides(args), **_effects_overrides(args.effects)}, where="--set")
    if args.texture == "photo" and sp.image is None:
        raise LeafsimError(f"--texture photo: species '{sp.key}' has no photo (drawn outline)")
    shape, veins, model = build_leaf(sp, params, args.seed)
    sim = Simulator(model, params, seed=args.seed)
    state = sim.state()
    keys = [state.copy()]

    def on_frame(k, st, stats):
        if args.every and k % args.every == 0:
            keys.append(st.copy())

    state, stats = run_headless(model, params, args.frames, on_frame=on_frame, state=state, simulator=sim)
    if any(s["nan"] for s in stats):
        raise LeafsimError(f"{sp.key}: the simulation produced NaN at frame {len(stats)}")
    if not args.every:
        keys = [state]
    elif keys[-1].frame != state.frame:
        keys.append(state.copy())
    photo = species_photo_rgba(sp, params) if sp.image is not None else None
    view = LeafView(model, photo, sim.state().pigments, photo_colour=sp.photo_colour)
    rep = export_mesh(model, keys, args.out, format=fmt, params=params, view=view,
                      layers=args.layers, veins=args.veins, texture=args.texture)
    rep.update(species=sp.key, seed=args.seed, frames=state.frame)
    counts = ", ".join(f"{k} {v['vertices']} vertices / {v['triangles']} triangles" for k, v in rep["meshes"].items())
    _emit(args, rep, f"{sp.key}: {counts}, {rep['targets']} morph targets -> {', '.join(rep['files'])}")


COMMANDS = {
    "gui": cmd_gui, "species": cmd_species, "params": cmd_params, "outline": cmd_outline, "veins": cmd_veins,
    "build": cmd_build, "run": cmd_run, "bench": cmd_bench, "compare": cmd_compare,
}
COMMANDS.update(scene=cmd_scene, export=cmd_export, accuracy=cmd_accuracy)

if __name__ == "__main__":
    sys.exit(main())
