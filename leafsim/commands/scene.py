"""``leafsim scene``: a scene file of many leaves, simulated in parallel (pool or Dask)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from leafsim.base.errors import LeafsimError
from leafsim.commands.common import emit, ready_kernels, warn
from leafsim.scene.run import load_scene, run_scene


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity where the OS tells it, else the count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _warn_unmeasured_substeps(scene) -> None:
    """One warning line per group whose simulated mesh runs XPBD substeps coarser than every
    measured quality level (:func:`~leafsim.sim.effects.dynamics.unmeasured_substeps`)."""
    from leafsim.config.species import get_species
    from leafsim.sim.effects import EFFECTS
    from leafsim.sim.effects.dynamics import unmeasured_substeps

    seen = set()
    for job in scene.jobs:
        group = job.meta.get("group")
        if group in seen:
            continue
        seen.add(group)
        p = get_species(job.species, job.config).params.with_overrides(job.overrides)
        if job.lod is not None:
            p = p.with_overrides({"mesh.spacing": job.lod["simulate"]})
        if job.effects is not None:  # the group's own effect list (the canopy's leaves: colour only)
            p = p.with_overrides({f"effects.{e}": e in job.effects for e in EFFECTS})
        coarse = unmeasured_substeps(p)
        if coarse:
            warn(f"{scene.path}: group {group!r}: {coarse}")


def cmd_scene(args):
    if args.out is not None and not args.out.strip():
        raise LeafsimError("--out '': expected a folder name for the scene's files (or leave --out out)")
    if args.scheduler is not None and not args.scheduler.strip():  # '' ran on the local pool without a word
        raise LeafsimError("--scheduler '': expected a Dask scheduler address (e.g. tcp://host:8786), or no --scheduler "
                           "for the local process pool")
    scene = load_scene(args.scene)
    cpus = usable_cpus()
    workers = args.workers if args.workers is not None else cpus
    if args.scheduler is None and min(workers, len(scene.jobs)) > cpus:
        warn(f"--workers {workers} is more than the CPUs this process may use ({cpus}): the leaves will share "
             f"cores (each worker holds its own leaf in memory; the results are the same for any worker count)")
    _warn_unmeasured_substeps(scene)
    out = Path(args.out) if args.out else Path("out") / Path(args.scene).stem
    if not args.out:  # the default out/NAME: its parent is leafsim's to make (--out's must exist)
        try:
            out.parent.mkdir(exist_ok=True)
        except OSError as e:
            raise LeafsimError(f"--out {out} (the default): cannot make the folder out ({e.strerror or e})") from None
    rep = run_scene(scene, out, workers=workers, scheduler=args.scheduler, before=ready_kernels)
    bad = rep["failed"]
    text = (f"{scene.name}: {rep['ran']} leaves simulated, {rep['skipped']} already done, {len(bad)} failed "
            f"in {rep['total_s']:.1f} s ({rep['leaves_per_s'] or 0:.3g} leaves/s) -> {out}")
    emit(args, rep, text)
    if bad:
        names = ", ".join(f"{b['name']} ({b['error']})" for b in bad)
        print(f"leafsim: scene {scene.name}: {len(bad)} of {rep['leaves']} leaves failed: {names}", file=sys.stderr)
        return 1
    return 0
