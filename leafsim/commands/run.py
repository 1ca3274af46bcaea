"""``leafsim run``: one leaf simulated headless, with per-frame statistics, offscreen PNG
frames, checkpoints every K frames and ``--resume``; Ctrl-C / SIGTERM finish the frame, save
a checkpoint and exit with one line."""

from __future__ import annotations

import json
import math
import signal
import os
import re
import time
from pathlib import Path

import numpy as np

from leafsim.appearance.photo import species_photo_rgba
from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output, no_folder, not_an_input, output_target, remove_stale_temps, same_file
from leafsim.base.signals import DeferredSignals, Interrupted
from leafsim.commands import CHECKPOINT, CHECKPOINT_EVERY
from leafsim.commands.common import Progress, emit, ready_kernels, species_inputs, species_params, stop_of
from leafsim.pipeline import build_leaf
from leafsim.render.sequence import FrameWriter
from leafsim.sim.checkpoint import check_meta, load_carry, load_checkpoint, save_checkpoint
from leafsim.sim.measures import leaf_measures
from leafsim.sim.run import Run, Stop
from leafsim.sim.shape import save_npz
from leafsim.sim.stats import StatsStream

#: the names --every writes its PNG frames under (leafsim.render.sequence.FrameWriter)
_FRAME_NAME = re.compile(r"frame_\d{5,}\.png", re.ASCII | re.IGNORECASE)  # (a case-blind file system too)


def _prior_seconds(meta: dict) -> float | None:
    """The simulation seconds a checkpoint's earlier invocations took, or None when it does not
    say (an older version's) or says something that is no number of seconds."""
    v = meta.get("sim_s_total")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
        return None
    return float(v)

def _npz_meta(args) -> str:
    """final.npz's ``meta``: the run's provenance (the --json object's) as JSON text."""
    import json

    from leafsim.base.provenance import provenance
    from leafsim.commands.common import RESOLVED

    return json.dumps(provenance(command=getattr(args, "command_line", None), **RESOLVED), sort_keys=True)

def check_run_args(args) -> Path | None:
    """Validate ``leafsim run``'s options before any work; returns the --out folder (or None)."""
    stop_of(args)  # --frames / --until: checked before any work
    if args.every < 0:
        raise LeafsimError(f"--every {args.every}: expected a non-negative frame interval")
    if args.every and not args.out:
        raise LeafsimError("--every needs --out DIR for the PNG frames")
    if args.checkpoint_every is not None and args.checkpoint_every < 0:
        raise LeafsimError(f"--checkpoint-every {args.checkpoint_every}: expected a non-negative frame interval")
    if (args.checkpoint_every or args.resume) and not args.out:
        raise LeafsimError(f"{'--resume' if args.resume else '--checkpoint-every'} needs --out DIR (the checkpoint lives there)")
    if args.out is not None and not args.out.strip():
        raise LeafsimError("--out '': expected a folder name for the run's files")
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.is_symlink() and not out.exists():
            raise LeafsimError(f"--out {out}: a broken symbolic link (expected a folder or nothing)")
        if out.exists() and not out.is_dir():
            raise LeafsimError(f"--out {out}: exists and is not a folder")
        if not out.parent.is_dir():
            raise LeafsimError(f"--out {out}: {no_folder(out.parent)}")
        check_output(out, "--out folder", folder=True)
        ck = out / CHECKPOINT
        if args.resume and (ck.exists() or ck.is_symlink()) and not ck.is_file():
            raise LeafsimError(f"--resume: {ck} is not a regular file (expected the checkpoint a run with --out {out} wrote)")
        if args.resume and not ck.is_file():
            raise LeafsimError(f"--resume: no checkpoint at {ck} (run first with --out {out})")
        if out.is_dir():
            # what the run will write there, checked now, not after the simulation
            output_target(out / "final.npz", "the final state")
            if args.checkpoint_every != 0:
                output_target(ck, "checkpoint")
            if args.every:
                for f in sorted(out.glob("frame_*.png")):
                    output_target(f, "PNG frame")
    if args.stats is not None and not args.stats.strip():
        raise LeafsimError("--stats '': expected a file name for the per-frame statistics")
    if args.stats:
        if not Path(args.stats).parent.is_dir():
            raise LeafsimError(f"--stats {args.stats}: {no_folder(Path(args.stats).parent)}")
        check_output(args.stats, "--stats file")
        if out is not None:
            if os.path.realpath(args.stats) == os.path.realpath(out):  # refused now, before --out is made
                raise LeafsimError(f"--stats {args.stats}: that is the --out folder (expected a file elsewhere)")
            mine = {os.path.realpath(out / n) for n in ("final.npz", CHECKPOINT)}
            stats = os.path.realpath(args.stats)
            if stats in mine or (args.every and Path(stats).parent == Path(os.path.realpath(out))
                                 and Path(stats).name.startswith("frame_")):
                raise LeafsimError(f"--stats {args.stats}: the run writes that file in --out {out} itself "
                                   "(expected another path)")
    if args.checkpoint_every is None:
        args.checkpoint_every = CHECKPOINT_EVERY if out is not None else 0
    return out


def _prepare_out(out: Path | None, ck: Path | None, stats: str | None) -> None:
    """Create --out and drop temp files a SIGKILLed run left while writing."""
    if out is not None:
        out.mkdir(exist_ok=True)
    for target in ([ck, out / "final.npz", out / "frame_*.png"] if out is not None else []) + ([Path(stats)] if stats else []):
        remove_stale_temps(target)


class _Outputs:
    """What ``leafsim run`` writes per frame: statistics lines, PNG frames, checkpoints."""

    def __init__(self, args, sp, params, run: Run, ck: Path | None, meta: dict, out: Path | None, start: int):
        self.args, self.run, self.ck, self.meta = args, run, ck, meta
        #: simulation seconds of the invocations before this one (a resumed run's checkpoint says;
        #: None when it does not: a checkpoint of an older version)
        self.prior_s = meta.get("sim_s_total")
        self.t_start = time.perf_counter()
        self.stream = StatsStream(args.stats, keep_until=start if args.resume else None) if args.stats else None
        self.frames = None
        if args.every:
            photo = species_photo_rgba(sp, params) if (sp.image is not None and params["render.texture"]) else None
            self.frames = FrameWriter(run.model, params, photo, out, run.sim.state(), sp.photo_colour)
            if start == 0:
                self.frames.write(0, run.state)

    def frame(self, st: dict, stopping: bool) -> None:
        k, a = self.run.state.frame, self.args
        if self.stream is not None:
            self.stream.write(st)
        if self.frames is not None and k % a.every == 0:
            self.frames.write(k, self.run.state)
        # a frame that produced NaN never replaces the last good checkpoint (--resume needs it)
        if self.ck is not None and a.checkpoint_every and (stopping or k % a.checkpoint_every == 0) and not st["nan"]:
            save_checkpoint(self.ck, self.run.model, self.run.state, self.timed_meta(), self.run.sim.carry())

    def timed_meta(self) -> dict:
        """The checkpoint's meta with the simulation seconds of every invocation so far."""
        total = None if self.prior_s is None else round(self.prior_s + time.perf_counter() - self.t_start, 3)
        return {**self.meta, "sim_s_total": total}

    def finish(self) -> None:
        """The run ended by its stop (not a signal): a --stats file exists even with no frame."""
        if self.stream is not None:
            self.stream.finish()

    def close(self) -> None:
        if self.stream is not None:
            self.stream.close()


def _simulate(run: Run, until: Stop, outputs: _Outputs, progress: Progress) -> tuple[list, int | None]:
    """Step until ``until`` holds (or NaN, or a signal); returns (statistics, signal or None)."""
    stats = []
    stopping = False
    try:
        with DeferredSignals() as stop:
            for ms in run.frames(until):
                st = run.stats(ms)
                stats.append(st)
                # read the flag once: a signal arriving after this line is acted on after the
                # next frame (checkpointed then), never by a break that skipped this frame's save
                stopping = stop.signum is not None
                outputs.frame(st, stopping)
                progress.update()
                if stopping or st["nan"]:
                    break
            if stop.signum is None:
                outputs.finish()
    finally:
        progress.close()
        outputs.close()
    # a signal that came after the last frame's check lets the finished run end normally
    return stats, stop.signum if stopping else None


def cmd_run(args):
    out = check_run_args(args)
    t0 = time.perf_counter()
    sp, params = species_params(args, effects=True)
    for path, option in ((args.stats, "--stats"), *(((out / n), "--out") for n in ("final.npz", CHECKPOINT) if out is not None)):
        if path is not None:
            not_an_input(path, species_inputs(sp), option)
    if out is not None and args.every:  # a photo kept as OUT/frame_00000.png became the first frame
        for src in species_inputs(sp):
            real = Path(os.path.realpath(src)) if src is not None else None  # (a link to such a file too)
            if real is not None and _FRAME_NAME.fullmatch(real.name) and same_file(real.parent, out):
                raise LeafsimError(f"--out {out}: --every {args.every} writes its frames as frame_NNNNN.png there, and the "
                                   f"input {src} is one of those names (expected another folder; it would be replaced)")
    # what a checkpoint must have been made with to be resumed by this command
    meta = {"species": sp.key, "config": str(Path(args.config).resolve()) if args.config else None,
            "seed": args.seed, "params": params.to_dict()}
    ck = out / CHECKPOINT if out is not None else None
    prior_s = 0.0
    if args.resume:
        prior_s = _prior_seconds(check_meta(ck, meta))  # before the build: a mismatch costs nothing
    ready_kernels()
    t0 = time.perf_counter()  # build_s: the build, not a first run's compile
    model = build_leaf(sp, params, args.seed).model
    build_s = time.perf_counter() - t0
    run = Run(model, params, seed=args.seed)
    if args.resume:
        run.state = load_checkpoint(ck, model, meta)
        run.sim.restore(load_carry(ck, model))
        if args.frames is not None and args.until is None and args.frames < run.state.frame:
            raise LeafsimError(f"--frames {args.frames}: the checkpoint in {out} is at frame {run.state.frame} already "
                               f"(resume with --frames ≥ {run.state.frame})")
    start = run.state.frame
    until = stop_of(args, start)
    _prepare_out(out, ck, args.stats)
    outputs = _Outputs(args, sp, params, run, ck, {**meta, "sim_s_total": prior_s}, out, start)
    t1 = outputs.t_start = time.perf_counter()
    stats, signum = _simulate(run, until, outputs, Progress(args, run, until, sp.key))
    sim_s = time.perf_counter() - t1
    if signum is not None:
        where = (f"checkpoint {ck}: continue with the same command and --resume" if ck is not None and args.checkpoint_every
                 else "no checkpoint (give --out DIR and --checkpoint-every K to be able to resume)")
        if args.json:  # the one JSON object still comes, saying where the run stopped
            rep = run_report(sp, params, args, run, stats, start, build_s, sim_s, outputs.frames, check_nan=False,
                             prior_s=outputs.prior_s)
            emit(args, {**rep, "interrupted": signal.Signals(signum).name}, "")
        goal = f" of {args.frames}" if args.until is None else f" (until {args.until})"
        raise Interrupted(signum, f"interrupted at frame {run.state.frame}{goal}"
                                  + (f", statistics in {args.stats}" if args.stats else "") + f"; {where}")
    broken = bool(stats) and stats[-1]["nan"]  # run_report below says so; keep the good files
    if ck is not None and args.checkpoint_every and not broken:
        save_checkpoint(ck, model, run.state, outputs.timed_meta(), run.sim.carry())  # the final state: --resume --frames M continues it
    if out is not None and not broken:
        save_npz(out / "final.npz", model, run.state, meta=_npz_meta(args))
    if outputs.frames is not None and run.state.frame % args.every:
        outputs.frames.write(run.state.frame, run.state)  # the last frame too (where --until stopped)
    rep = run_report(sp, params, args, run, stats, start, build_s, sim_s, outputs.frames, prior_s=outputs.prior_s)
    emit(args, rep, run_text(rep, out, ck if args.checkpoint_every else None))


def run_text(rep: dict, out: Path | None, ck: Path | None) -> str:
    """The few lines a person reads after ``leafsim run`` (``--json`` gives every number)."""
    stalk = rep.get("petiole_water_fraction")
    lines = [f"{rep['species']}, seed {rep['seed']}: frame {rep['frame']} ({rep['frames']} frames run"
             + (f", resumed from {rep['resumed_from']}" if rep["resumed_from"] else "") + "), "
             f"{100 * rep['water_fraction']:.1f} % of the blade's water left"
             + (f" (stalk {100 * stalk:.0f} %)" if stalk is not None else "") + "; "
             f"{rep['build_s']:.1f} s building, {rep['sim_s']:.1f} s simulating ({_frame_costs(rep)})",
             f"shape: 3D area kept {100 * rep['shape_area_ratio']:.1f} %, margin lift {rep['shape_margin_lift']:.3f} L, "
             f"margin roll {rep.get('shape_margin_roll_deg', 0.0):.0f}°, midrib fold {rep.get('shape_midrib_fold_deg', 0.0):.0f}°, "
             f"lamina crinkle {rep.get('shape_crinkle_slope_rms_deg', 0.0):.1f}° RMS ({rep.get('shape_crinkle_excess_pct', 0.0):.2f} % excess length)"
             + (f", {rep['shape_inverted']} inverted triangles" if rep.get("shape_inverted") else "")]
    wrote = [str(out / "final.npz")] if out is not None else []
    if ck is not None:
        wrote.append(str(ck))
    if rep["png_frames"]:
        wrote.append(f"{rep['png_frames']} frame pictures in {out}")
    if wrote:
        lines.append("wrote " + ", ".join(wrote))
    lines.append("(every number: --json)")
    return "\n".join(lines)


def _frame_costs(rep: dict) -> str:
    """What a frame cost: the mean, and on the drying path the two meshes' frames apart (the
    leaf's own mesh costs several times a path frame, so a median alone hid where the time went)."""
    phases = rep.get("phases") or {}
    text = f"{rep['ms_per_frame_mean']:.1f} ms a frame on average"
    if phases.get("path", {}).get("frames") and (phases.get("own", {}).get("frames") or phases.get("middle", {}).get("frames")):
        p, o = phases["path"], phases["own"]
        mid = phases.get("middle", {})
        parts = [f"{p['frames']} on the coarse drying-path mesh at {p['ms_mean']:.1f} ms"]
        if mid.get("frames"):
            parts.append(f"{mid['frames']} on the default mesh at {mid['ms_mean']:.1f} ms")
        if o.get("frames"):
            parts.append(f"{o['frames']} on the leaf's own mesh at {o['ms_mean']:.1f} ms")
        text += ": " + ", ".join(parts)
    return text


def _path_depth(model) -> int:
    """How many drying-path meshes lie under ``model`` (0, 1, or 2 with ``dynamics.path = fine``)."""
    depth = 0
    while model.path is not None:
        depth, model = depth + 1, model.path
    return depth


def _phases(stats, depth: int = 1) -> dict:
    """Frames and their summed stage milliseconds on the drying path's coarsest mesh, on the
    leaf's own mesh and, with nested paths (``depth`` 2: ``dynamics.path = fine``), on the
    default mesh between them (``middle``; ``mesh`` of each frame's stats)."""
    def mesh(s) -> int:
        return int(s.get("mesh", 1 if s.get("on_path") else 0))

    out = {}
    for name, keep in (("path", lambda k: k > 0 and k == depth), ("middle", lambda k: 0 < k < depth), ("own", lambda k: k == 0)):
        if name == "middle" and depth < 2:
            continue
        ms = [sum(s["ms"].values()) for s in stats if keep(mesh(s))]
        out[name] = {"frames": len(ms), "s": round(sum(ms) / 1e3, 3),
                     "ms_mean": round(float(np.mean(ms)), 4) if ms else 0.0}
    return out


def run_report(sp, params, args, run: Run, stats, start, build_s, sim_s, frames, check_nan: bool = True,
               prior_s: float | None = 0.0) -> dict:
    """The ``leafsim run`` report (LeafsimError when the run produced NaN and ``check_nan``).
    ``frames``, ``sim_s`` and the per-frame figures are this invocation's (from ``resumed_from``
    on); ``sim_s_total`` adds the simulation seconds of the invocations before it (``prior_s``,
    kept in the checkpoint).
    ``water_kg`` is the water left now, ``fresh_water_kg`` the fresh leaf's (blade and petiole);
    ``water_fraction`` is the blade's (:meth:`Model.water_fraction`: the petiole dries last)."""
    model, state = run.model, run.state
    ms = [sum(s["ms"].values()) for s in stats]
    rep = {
        "species": sp.key, "seed": args.seed, "frames": len(stats), "frame": state.frame, "resumed_from": start,
        "build_s": round(build_s, 3), "sim_s": round(sim_s, 3),
        "sim_s_total": None if prior_s is None else round(prior_s + sim_s, 3),
        "ms_per_frame_median": round(float(np.median(ms)), 4) if ms else 0.0,
        "ms_per_frame_mean": round(float(np.mean(ms)), 4) if ms else 0.0,
        "phases": _phases(stats, _path_depth(model)),
        "weather_hours": round(state.weather_time / 3600.0, 4) if params["environment.drive"] == "weather" else None,
        "until": args.until,
        "nan": bool(any(s.get("nan") for s in stats)),
        "png_frames": 0 if frames is None else frames.written,
        **leaf_measures(model, state, params),  # (the library's call for the same numbers)
        **model.to_report(),
    }
    if rep["nan"] and check_nan:
        raise LeafsimError(f"{sp.key}: the simulation produced NaN at frame {state.frame} (parameters: {params.changed()})")
    return rep
