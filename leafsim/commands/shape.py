"""``leafsim outline``, ``veins`` and ``build``: the first three stages, one at a time."""

from __future__ import annotations

import json
import time

from leafsim.appearance.draw2d import draw_veins
from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import write_png_atomic
from leafsim.commands.common import emit, png_output, species_params, warn
from leafsim.config.params import ParamSet, parse_set_args
from leafsim.outline.image import load_image
from leafsim.outline.report import draw_outline, outline_report
from leafsim.outline.trace import trace_outline
from leafsim.pipeline import build_leaf, leaf_shape, species_veins


def cmd_outline(args):
    png_output("--out", args.out, (args.image,))
    sets = parse_set_args(args.sets)
    other = sorted(k for k in sets if not (k.startswith("outline.") or k == "limits.image_pixels"))
    if other:  # tracing reads no other parameter: it would be ignored silently
        raise LeafsimError(f"--set {other[0]}: outline traces the photo only (expected outline.* or limits.image_pixels)")
    params = ParamSet(sets)
    traced = trace_outline(args.image, params)
    rep = outline_report(traced)
    for problem in rep["leafness"]["problems"]:  # reported, never silent (build and compare refuse them)
        refused = " (veins, build, run, compare and the window refuse this photo)" if problem["level"] == "refuse" else ""
        warn(f"{args.image}: {problem['text']}{refused}")
    if args.out:
        draw_outline(traced, load_image(args.image), args.out)
    emit(args, rep, f"{args.image}: {rep['points']} points, area {rep['area_px']:.0f} px, base {rep['base']}, apex {rep['apex']}, "
                    f"{len(rep['lobes'])} lobe tips, IoU {rep['iou']:.4f}" + (f" -> {args.out}" if args.out else ""))


def _photo_laterals(test) -> str:
    """The text line's note on a photo's laterals: traced, or grown because the photo shows none."""
    if not test:
        return ""
    if test["shown"] and test["traced"]:
        return f"; {test['traced']} laterals traced from the photo"
    if test["shown"]:
        return "; no lateral traced from the photo survived its checks: laterals grown"
    return (f"; the photo shows no laterals above its texture (strongest path {test['best']:.2f} against "
            f"{test['null']:.2f} in the shuffled blade): laterals grown")


def cmd_veins(args):
    sp, params = species_params(args)
    png_output("--out", args.out, (sp.image,))
    t0 = time.perf_counter()
    shape = leaf_shape(sp, params)
    graph = species_veins(sp, shape, params, args.seed)
    dt = time.perf_counter() - t0
    rep = {"species": sp.key, "seed": args.seed, "length_m": sp.length_m, **graph.stats}
    if args.out:
        photo = load_image(sp.image) if sp.image is not None else None
        write_png_atomic(args.out, draw_veins(shape, graph, photo=photo))
    c = graph.stats["counts"]
    emit(args, rep, f"{sp.key} seed {args.seed}: main {c['main']}, lateral {c['lateral']}, sublateral {c['sublateral']}, net {c['net']}; "
                    f"crossings {graph.stats['crossings']}, outside {graph.stats['outside_length']:.3g} m ({dt * 1000:.0f} ms)"
                    + _photo_laterals(graph.stats.get("photo_laterals"))
                    + (f" -> {args.out}" if args.out else ""))


def cmd_build(args):
    sp, params = species_params(args)
    model = build_leaf(sp, params, args.seed).model
    rep = {"species": sp.key, "seed": args.seed, **model.to_report()}
    emit(args, rep, json.dumps(rep, indent=1, sort_keys=True))
