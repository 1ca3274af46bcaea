"""``leafsim compare``: the model top-down beside the species photo (and a senescent one)."""

from __future__ import annotations

from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import write_png_atomic
from leafsim.commands.common import Progress, emit, png_output, ready_kernels, species_params
from leafsim.compare.metrics import montage
from leafsim.compare.run import DRY_LEFT, MAX_FRAMES, run_compare
from leafsim.sim.run import Stop


def stage_arg(text: str | None):
    """``--stage``: young, dried or a frame number."""
    if text is None or text in ("young", "dried"):
        return text
    t = text.strip().lstrip("+")
    k = int(t) if t.isascii() and t.isdigit() and len(t) <= 9 else -1  # int() takes '1_0' and '٣' too
    if not 0 <= k <= MAX_FRAMES:
        raise LeafsimError(f"--stage {text[:24]!r}{'…' if len(text) > 24 else ''}: expected young, dried or a frame number from 0 to {MAX_FRAMES} "
                           "(compare dries the leaf at most that far)")
    return k


def cmd_compare(args):
    stage = stage_arg(args.stage)
    if args.photo is not None and not Path(args.photo).is_file():
        raise LeafsimError(f"--photo {args.photo}: " + ("not a regular file (a folder, a device or a pipe), expected an image"
                                                          if Path(args.photo).exists() else "file not found"))
    sp, params = species_params(args, effects=True)
    png_output("--out", args.out, (args.photo, sp.image, sp.senescent.image if sp.senescent is not None else None))
    if args.photo is None and sp.image is None:  # before the kernels compile (run_compare says the same)
        raise LeafsimError(f"species '{sp.key}' has no photo (drawn outline): give --photo IMAGE to compare with")
    ready_kernels()
    bar: list = []

    def progress(run):  # a bar toward "dry" on a terminal (none with --json)
        if not bar:
            bar.append(Progress(args, run, Stop(water_left=DRY_LEFT), f"{sp.key} drying"))
        bar[0].update()

    try:
        rep = run_compare(sp, params, seed=args.seed, photo=args.photo, stage=stage, progress=progress)
    finally:
        if bar:
            bar[0].close()
    rows = rep.pop("_rows")
    if args.out:
        write_png_atomic(args.out, montage(rep, rows), rgb=True)
        rep["montage"] = str(args.out)
    lines = [f"{sp.key}: {'row':9s} {'frame':>6s} {'water':>6s} {'IoU':>7s} {'margin':>7s} {'colourTV':>8s} {'dE':>6s}  reference"]
    for r in rep["rows"]:
        m = "n/a" if r["margin_ratio"] is None else f"{r['margin_ratio']:.3f}"
        lines.append(f"{sp.key}: {r['kind']:9s} {r['stage']['frame']:6d} {r['stage']['water']:6.2f} {r['iou']:7.4f} {m:>7s} "
                     f"{r['colour_tv']:8.3f} {r['mean_delta_e'] or 0:6.1f}  {r['reference']}")
    emit(args, rep, "\n".join(lines) + (f"\n-> {args.out}" if args.out else ""))
